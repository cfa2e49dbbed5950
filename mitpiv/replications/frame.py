"""Replications of the published studies mitpiv was designed from (``mitpiv replicate NAME``).

The standard every replication follows is the project's REPLICATION.md: the paper's set-up,
the paper's measures by the paper's definitions, every sweep axis the paper has, the
headline results side by side with ours, every disagreement investigated, and (its second
edition, points 7-13) agreement that means something. This module is the frame they share;
each study is a sub-package of :mod:`mitpiv.replications` whose ``study`` module defines
``STUDY = Study(...)`` with a ``run(ctx) -> ReplicationResult`` function.

Rows (:class:`Row`) carry a ``kind``: ``physics`` (a prediction from inputs that do not
contain the answer), ``input``, ``definition`` or ``info``; only physics rows are counted.
A study declares the kinds of its rows and the paper results it used as model inputs
(:attr:`Study.kinds`, :attr:`Study.inputs_from_paper`); :func:`classify_rows` applies and
checks them (a physics row may read no paper result, must compare something, and every
other row says why). :func:`compare_value` and :func:`compare_trend` take the values of
independent realisations and compare their 95 % interval with the paper's band: the verdict
is ``agrees``, ``disagrees`` or ``inconclusive`` (:func:`verdict`).

A replication run writes into its output folder:

- ``results.json``: the keys of :data:`RESULTS_KEYS`: the study, the scale (``full`` or
  ``quick``), the commit and the code hash that computed it, the tally of physics rows per
  arm, the points computed and read back (with the commit of each cached point), the
  study's inputs from the paper, one row per compared quantity and every swept series as a
  :class:`Curve`;
- ``report.md``: its first line the generated tally ("k of n physics rows agree, m
  disagree, j inconclusive (arm ...)"), the physics rows, the rows not counted in a table
  of their own (each with why), the study's own sections and its figures (PNG files beside
  it);
- ``work/``: intermediates (run folders, cached point results). A rerun resumes from them:
  every expensive point goes through :meth:`ReplicationContext.cached` or
  :meth:`ReplicationContext.map`, which store each point's JSON result with the code that
  computed it (:func:`code_hash`: the mitpiv version and the source of every mitpiv module
  the study imports) and its commit. A point stored by other code is computed again; a
  full-scale result mixing commits is refused unless ``--allow-mixed`` says so in the report.

The quick scale (``--quick``) runs the same code with the same row ids on a reduced problem
(minutes on 2 cores); the tests run it. Both scales are written by the same writer, which
refuses duplicate ids and a missing required id. :func:`reclassify` applies a study's
current kinds to results written earlier, without recomputing a point.
"""

from __future__ import annotations

import fnmatch
import importlib
import json
import logging
import math
import subprocess
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any

from mitpiv.errors import ConfigError
from mitpiv.progress import Progress, bar

__all__ = ["Row", "Kind", "Curve", "Study", "ReplicationContext", "ReplicationResult", "compare_value",
           "compare_trend", "interval", "Pooled", "pooled_bootstrap", "verdict", "classify_rows", "unused_kinds", "tally", "tally_line", "code_hash",
           "code_modules", "replicate", "reclassify", "get_study", "list_studies", "write_outputs", "RESULTS_KEYS",
           "KINDS", "ARMS", "VERDICTS"]

log = logging.getLogger(__name__)

#: Top-level keys of results.json (REPLICATION.md, point 5).
RESULTS_KEYS = ("study", "title", "paper", "scale", "commit", "mitpiv_version", "code_hash", "command", "wall_s",
                "tally", "points_computed", "points_cached", "cached_point_commits", "mixed_commits",
                "inputs_from_paper", "rows", "curves", "figures")


# ------------------------------------------------------------------------------ rows and curves
#: what a row is (REPLICATION.md, point 7): only ``physics`` rows are counted
KINDS = ("physics", "input", "definition", "info")
#: which image model produced a row (point 13)
ARMS = ("paper-model", "physical")
#: the outcome of a comparison (point 9); ``not compared`` where the paper gives no comparable value
VERDICTS = ("agrees", "disagrees", "inconclusive", "not compared")
#: confidence level of every interval
CI_LEVEL = 0.95


@dataclass(frozen=True)
class Row:
    """One compared quantity of a replication.

    Attributes
    ----------
    id : str
        A stable name other tools read (``Q_D0``, ``ltpr_cross_nc4``).
    quantity : str
        What it is, in words.
    paper_source : str
        Where it is in the paper (``Fig. 4-1``, ``Table 1``).
    paper, ours
        The paper's value or trend, and ours (numbers, or text for a trend); with several
        realisations ``ours`` is their mean.
    unit : str
        The unit of ``paper`` and ``ours`` ("" for dimensionless).
    tolerance : str
        The band we hold ourselves to, and why (in words): how precisely the paper's value
        can be read, never our result.
    agrees : bool or None
        True / False where the verdict is agrees / disagrees, else None (kept for the
        readers of earlier results; ``verdict`` is the three-valued outcome).
    note : str
        The cause of a disagreement, a caveat or a crop.
    kind : str
        ``physics`` (a prediction from inputs that do not contain the answer), ``input``
        (set from, or following directly from, a result the paper reports), ``definition``
        (true by construction, or arithmetic on the paper's numbers) or ``info`` (context,
        not compared). Only physics rows are counted.
    arm : str
        ``paper-model`` (the paper's own image model) or ``physical`` (rendered by Mitsuba).
    verdict : str
        ``agrees``, ``disagrees``, ``inconclusive`` (the interval is too wide to tell the two
        apart) or ``not compared``; derived from ``agrees`` when not given.
    ci : tuple of float or None
        The 95 % interval ``(lo, hi)`` of ``ours`` over the realisations (None with one).
    n : int
        The number of independent realisations behind ``ours``.
    ci_method : str
        How ``ci`` was computed (``t``: Student-t on the mean; ``bootstrap``).
    reads : tuple of str
        The study's declared paper inputs (:attr:`Study.inputs_from_paper`) the value
        depends on; a physics row may read none.
    why : str
        Why the row has its kind (required for non-physics rows), or a caveat of a physics
        row; printed with the row, pass or fail.
    """

    id: str
    quantity: str
    paper_source: str
    paper: Any
    ours: Any
    unit: str = ""
    tolerance: str = ""
    agrees: bool | None = None
    note: str = ""
    kind: str = "physics"
    arm: str = "paper-model"
    verdict: str | None = None
    ci: tuple[float, float] | None = None
    n: int = 1
    ci_method: str = ""
    reads: tuple[str, ...] = ()
    why: str = ""

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ConfigError(f"row {self.id!r}: kind {self.kind!r} is not one of {KINDS}.")
        if self.arm not in ARMS:
            raise ConfigError(f"row {self.id!r}: arm {self.arm!r} is not one of {ARMS}.")
        verdict = self.verdict
        if verdict is None:
            verdict = "not compared" if self.agrees is None else ("agrees" if self.agrees else "disagrees")
        if verdict not in VERDICTS:
            raise ConfigError(f"row {self.id!r}: verdict {verdict!r} is not one of {VERDICTS}.")
        object.__setattr__(self, "verdict", verdict)
        object.__setattr__(self, "agrees", {"agrees": True, "disagrees": False}.get(verdict))
        if self.ci is not None:
            lo, hi = (float(v) for v in self.ci)
            object.__setattr__(self, "ci", (lo, hi))
        if not isinstance(self.n, int) or isinstance(self.n, bool) or self.n < 1:
            raise ConfigError(f"row {self.id!r}: n (realisations) must be an integer >= 1, got {self.n!r}.")
        object.__setattr__(self, "reads", tuple(self.reads))

    @classmethod
    def from_dict(cls, d: Mapping) -> Row:
        """A row from its results.json form (keys a row does not have are ignored; an earlier
        writer's row, without kind or verdict, is a physics row judged by its ``agrees``)."""
        names = {f.name for f in fields(cls)}
        kw = {k: v for k, v in d.items() if k in names}
        if kw.get("ci") is not None:
            kw["ci"] = tuple(kw["ci"])
        return cls(**kw)


@dataclass(frozen=True)
class Kind:
    """How a study declares a row's kind (:attr:`Study.kinds`): the kind, why (printed with
    the row; required unless physics) and the declared paper inputs the row's value reads."""

    kind: str
    why: str = ""
    reads: tuple[str, ...] = ()

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ConfigError(f"Kind: kind {self.kind!r} is not one of {KINDS}.")
        object.__setattr__(self, "reads", tuple(self.reads))


def _finite_or_none(v):
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def interval(samples: Sequence[float], *, method: str = "t", level: float = CI_LEVEL) -> tuple[float, float] | None:
    """The ``level`` confidence interval of the mean of ``samples`` (independent realisations).

    method : ``t`` (Student-t: mean +- t_{(1+level)/2, n-1} s / sqrt(n)) or ``bootstrap``
        (scipy.stats.bootstrap, percentile, 9999 resamples, a fixed seed: the same samples
        give the same interval). None for fewer than two samples or non-finite ones.
    """
    import numpy as np

    x = np.asarray(samples, dtype=np.float64).ravel()
    if x.size < 2 or not np.all(np.isfinite(x)):
        return None
    if method == "t":
        from scipy import stats

        half = stats.t.ppf(0.5 + level / 2, x.size - 1) * x.std(ddof=1) / math.sqrt(x.size)
        m = float(x.mean())
        return (m - float(half), m + float(half))
    if method == "bootstrap":
        if np.ptp(x) == 0:
            return (float(x[0]), float(x[0]))
        from scipy import stats

        r = stats.bootstrap((x,), np.mean, confidence_level=level, n_resamples=9999, method="percentile",
                            random_state=np.random.default_rng(0))
        return (float(r.confidence_interval.low), float(r.confidence_interval.high))
    raise ConfigError(f"interval: method {method!r} is not 't' or 'bootstrap'.")


@dataclass(frozen=True)
class Pooled:
    """A statistic pooled over ``n`` independent realisations (a model error's s.d. over every
    matched pair of every impact, as a paper pools its image pairs) with its 95 % interval
    ``ci`` from resampling the realisations (:func:`pooled_bootstrap`): pass it as ``ours``
    of :func:`compare_value` where the per-realisation values are too few to stand alone."""

    value: float
    ci: tuple[float, float] | None
    n: int


def pooled_bootstrap(groups: Sequence, statistic, *, level: float = CI_LEVEL, n_resamples: int = 999,
                     seed: int = 0):
    """``statistic(groups)`` (a float, or a dict of floats, from a list of realisations' data)
    and its ``level`` percentile interval from resampling the realisations with replacement
    (``n_resamples`` draws of their indices from a seeded generator: the same data give the
    same interval; every key of a dict shares the draws). Returns a :class:`Pooled`, or a
    dict of them. An interval is None below two realisations, or when fewer than half of the
    resamples give a finite value; non-finite resamples are dropped. Hand-written because
    scipy.stats.bootstrap resamples values, not groups of them with one statistic over all."""
    import numpy as np

    groups = list(groups)
    value = statistic(groups)
    many = isinstance(value, Mapping)
    values = {k: float(v) for k, v in value.items()} if many else {"": float(value)}
    n = max(len(groups), 1)
    draws: dict[str, list[float]] = {k: [] for k in values}
    if len(groups) >= 2:
        rng = np.random.default_rng(seed)
        for row in rng.integers(0, len(groups), size=(int(n_resamples), len(groups))):
            got = statistic([groups[i] for i in row])
            for k in values:
                draws[k].append(float(got[k] if many else got))
    out = {}
    for k, v in values.items():
        d = np.asarray(draws[k], dtype=np.float64)
        good = d[np.isfinite(d)]
        ci = None
        if math.isfinite(v) and d.size and good.size >= 0.5 * d.size:
            lo, hi = np.quantile(good, [0.5 - level / 2, 0.5 + level / 2])
            ci = (float(lo), float(hi))
        out[k] = Pooled(v, ci, n)
    return out if many else out[""]


def verdict(lo: float, hi: float, band_lo: float, band_hi: float) -> str:
    """Compare an interval ``[lo, hi]`` of ours with the paper's band ``[band_lo, band_hi]``
    (either end may be infinite: a one-sided claim such as '< 0.75' or '> 0').

    - ``disagrees``: the interval misses the band;
    - ``agrees``: the interval lies inside the band, or meets it and is no wider than a
      finite band (it is at least as precise as the paper's value can be read);
    - ``inconclusive``: it meets the band but straddles an edge while wider than the band
      (always so for a one-sided band): the realisations cannot tell agreement from
      disagreement.

    A single value (``lo == hi``) is never inconclusive.
    """
    if hi < band_lo or lo > band_hi:
        return "disagrees"
    if band_lo <= lo and hi <= band_hi:
        return "agrees"
    if math.isfinite(band_hi - band_lo) and (hi - lo) <= (band_hi - band_lo):
        return "agrees"
    return "inconclusive"


def _samples(id: str, ours) -> tuple[list[float], bool]:
    """``ours`` as a list of floats (one value, or the realisations) and whether it was a sequence."""
    import numpy as np

    if ours is None:
        return [float("nan")], False
    if isinstance(ours, (int, float, np.floating, np.integer)):
        return [float(ours)], False
    try:
        vals = [float(v) if v is not None else float("nan") for v in ours]
    except TypeError as e:
        raise ConfigError(f"row {id!r}: ours must be a number or a sequence of realisations, got "
                          f"{type(ours).__name__}.") from e
    if not vals:
        raise ConfigError(f"row {id!r}: ours is an empty sequence; give at least one realisation.")
    return vals, True


def _judge(id: str, ours, band_lo: float, band_hi: float, ci_method: str) -> dict:
    """ours (one value, realisations or a :class:`Pooled`) against a band: the Row fields ours,
    verdict, ci, n."""
    if isinstance(ours, Pooled):
        if not math.isfinite(ours.value):
            return {"ours": None, "verdict": "disagrees", "ci": None, "n": ours.n, "extra": "no finite value"}
        lo, hi = ours.ci if ours.ci is not None else (ours.value, ours.value)
        return {"ours": ours.value, "verdict": verdict(lo, hi, band_lo, band_hi), "ci": ours.ci, "n": ours.n,
                "extra": "", "method": "pooled bootstrap"}
    vals, many = _samples(id, ours)
    n = len(vals)
    if not all(math.isfinite(v) for v in vals):
        bad = sum(1 for v in vals if not math.isfinite(v))
        return {"ours": None, "verdict": "disagrees", "ci": None, "n": n,
                "extra": f"{bad} of {n} realisation(s) gave no finite value" if many else ""}
    mean = sum(vals) / n
    ci = interval(vals, method=ci_method) if n >= 2 else None
    lo, hi = ci if ci is not None else (mean, mean)
    return {"ours": mean, "verdict": verdict(lo, hi, band_lo, band_hi), "ci": ci, "n": n, "extra": "",
            "method": ci_method}


def compare_value(id: str, quantity: str, paper_source: str, paper: float, ours, *, unit: str = "",
                  rel: float | None = None, abs: float | None = None, note: str = "", why: str = "",
                  kind: str = "physics", arm: str = "paper-model", reads: Sequence[str] = (),
                  ci_method: str = "t") -> Row:
    """A numeric row: the paper's band is ``paper +- max(abs, rel * |paper|)``.

    Parameters
    ----------
    ours : float, sequence of float or Pooled
        One value, or the values of independent realisations (seeds, patches, particle
        fields): then ``ours`` is their mean, ``ci`` its 95 % interval (``ci_method``) and
        the verdict compares the interval with the band (:func:`verdict`); one value is
        judged as a point (``n = 1``, no interval); a :class:`Pooled` statistic brings its
        own interval (``ci_method`` "pooled bootstrap"). A non-finite value (or
        realisation) never agrees (and ``ours`` is written as null).
    rel, abs : float
        The relative and absolute tolerances (at least one). ``why`` says where the
        tolerance comes from (the paper's reading precision, ...); it is appended to the
        tolerance text.
    """
    if rel is None and abs is None:
        raise ConfigError(f"compare_value({id!r}): give a tolerance, rel= or abs= (e.g. rel=0.1 for 10 %).")
    paper_f = float(paper)
    tol = max(abs or 0.0, (rel or 0.0) * math.fabs(paper_f))
    j = _judge(id, ours, paper_f - tol, paper_f + tol, ci_method)
    parts = []
    if rel is not None:
        parts.append(f"±{rel * 100:g} %")
    if abs is not None:
        parts.append(f"±{abs:g}{(' ' + unit) if unit else ''}")
    text = " or ".join(parts) + (f" ({why})" if why else "")
    note = "; ".join(s for s in (note, j["extra"]) if s)
    return Row(id=id, quantity=quantity, paper_source=paper_source, paper=paper_f, ours=_finite_or_none(j["ours"]),
               unit=unit, tolerance=text, verdict=j["verdict"], note=note, kind=kind, arm=arm, ci=j["ci"], n=j["n"],
               ci_method=j.get("method", ci_method) if j["ci"] is not None else "", reads=tuple(reads))


def compare_trend(id: str, quantity: str, paper_source: str, paper: str, ours, agrees: bool | None = None, *,
                  samples: Sequence[float] | None = None, lower: float = -math.inf, upper: float = math.inf,
                  unit: str = "", tolerance: str = "", note: str = "", kind: str = "physics",
                  arm: str = "paper-model", reads: Sequence[str] = (), ci_method: str = "t") -> Row:
    """A trend row (a sign, an ordering, a crossing).

    Either the study's code decides ``agrees`` from one realisation, or it gives ``samples``:
    the trend's statistic in each independent realisation (a difference whose sign is the
    trend, a slope, ...) and the band ``[lower, upper]`` the paper's trend means (``lower=0``
    for 'rises'); the verdict then compares their 95 % interval with the band
    (:func:`verdict`), and ``ours`` stays the study's text or number for the table.
    """
    ci, n, v = None, 1, None
    if samples is not None:
        if agrees is not None:
            raise ConfigError(f"compare_trend({id!r}): give agrees= or samples=, not both (the samples decide).")
        if not (lower > -math.inf or upper < math.inf):
            raise ConfigError(f"compare_trend({id!r}): samples need the trend's band, lower= and/or upper= "
                              "(e.g. lower=0 for a rise).")
        j = _judge(id, samples, float(lower), float(upper), ci_method)
        ci, n, v = j["ci"], j["n"], j["verdict"]
        note = "; ".join(s for s in (note, j["extra"]) if s)
        if not tolerance:
            tolerance = ("> " + f"{lower:g}" if upper == math.inf else "< " + f"{upper:g}" if lower == -math.inf
                         else f"in [{lower:g}, {upper:g}]")
    else:
        v = "not compared" if agrees is None else ("agrees" if agrees else "disagrees")
    return Row(id=id, quantity=quantity, paper_source=paper_source, paper=paper, ours=_finite_or_none(ours),
               unit=unit, tolerance=tolerance, verdict=v, note=note, kind=kind, arm=arm, ci=ci, n=n,
               ci_method=ci_method if ci is not None else "", reads=tuple(reads))


@dataclass
class Curve:
    """A swept series: ``x`` and one list of y values per label; the paper's values (where it
    gives numbers) in ``paper`` (per label), at ``paper_x`` (default: ``x``)."""

    x: list
    y: dict[str, list]
    x_label: str = ""
    y_label: str = ""
    paper: dict[str, list] | None = None
    paper_x: list | None = None

    def to_dict(self) -> dict:
        d = {"x": list(self.x), "y": {k: list(v) for k, v in self.y.items()}, "x_label": self.x_label,
             "y_label": self.y_label}
        if self.paper is not None:
            d["paper"] = {k: list(v) for k, v in self.paper.items()}
            d["paper_x"] = list(self.paper_x if self.paper_x is not None else self.x)
        return d


@dataclass
class ReplicationResult:
    """What a study's ``run`` returns: its rows, curves, report sections (Markdown) and figures
    (file names returned by :meth:`ReplicationContext.figure`)."""

    rows: list[Row]
    curves: dict[str, Curve] = field(default_factory=dict)
    sections: list[str] = field(default_factory=list)
    figures: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class Study:
    """A replication: its CLI name, the paper's file in the shared seeds folder, a title, the
    ``run(ctx)`` function and the row ids every run (full or quick) must produce.

    kinds : row id (or fnmatch pattern, e.g. ``ltpr_*``) -> :class:`Kind`; an exact id wins,
        else the first matching pattern in order. Rows matching none are ``physics``.
    inputs_from_paper : name -> the result of the paper used as a model input (a count, a
        mean size, a fitted factor). A row whose value depends on one declares it in
        ``reads`` and cannot be ``physics`` (REPLICATION.md, point 8).
    """

    name: str
    paper: str
    title: str
    run: Callable[[ReplicationContext], ReplicationResult]
    required_ids: tuple[str, ...] = ()
    describe: str = ""
    kinds: Mapping[str, Kind] = field(default_factory=dict)
    inputs_from_paper: Mapping[str, str] = field(default_factory=dict)


def _kind_of(study: Study, row_id: str) -> Kind | None:
    if row_id in study.kinds:
        return study.kinds[row_id]
    for pattern, k in study.kinds.items():
        if fnmatch.fnmatchcase(row_id, pattern):
            return k
    return None


def classify_rows(study: Study, rows: Sequence[Row]) -> list[Row]:
    """The rows with the study's declared kinds applied (:attr:`Study.kinds`), checked against
    the second edition's rules (REPLICATION.md, points 7-8):

    - a row declared by the study gets its kind, ``why`` and ``reads`` (a kind given when
      the row was made must not contradict the declaration);
    - a row may read only declared paper inputs, and a physics row none of them: a value
      set from the paper's result is an ``input`` row, not a prediction;
    - a physics row must compare something (a paper value and a verdict): else it is ``info``;
    - every row that is not physics says why.
    """
    out = []
    for r in rows:
        k = _kind_of(study, r.id)
        if k is not None:
            if r.kind != "physics" and r.kind != k.kind:
                raise ConfigError(f"replication {study.name}: row {r.id!r} was made as kind {r.kind!r} but the "
                                  f"study declares it {k.kind!r}; keep one.")
            r = replace(r, kind=k.kind, why=k.why or r.why, reads=tuple(dict.fromkeys(r.reads + k.reads)))
        unknown = [x for x in r.reads if x not in study.inputs_from_paper]
        if unknown:
            raise ConfigError(f"replication {study.name}: row {r.id!r} reads {unknown}, which the study does not "
                              f"declare in inputs_from_paper (declared: {sorted(study.inputs_from_paper)}).")
        if r.kind == "physics" and r.reads:
            raise ConfigError(f"replication {study.name}: row {r.id!r} is a physics row but its value reads the "
                              f"paper's result(s) {list(r.reads)} ({study.inputs_from_paper[r.reads[0]]}); declare it "
                              "Kind('input', why=...) in the study's kinds: it cannot predict what it was given.")
        if r.kind == "physics" and r.verdict == "not compared":
            raise ConfigError(f"replication {study.name}: row {r.id!r} is a physics row but compares nothing (no "
                              "paper value, no verdict); declare it Kind('info', why=...) in the study's kinds.")
        if r.kind != "physics" and not r.why.strip():
            raise ConfigError(f"replication {study.name}: row {r.id!r} is kind {r.kind!r} without a reason; give "
                              "Kind(..., why='...'): the report prints it.")
        out.append(r)
    return out


def unused_kinds(study: Study, rows: Sequence[Row]) -> list[str]:
    """The keys of :attr:`Study.kinds` that no row matches (a stale declaration)."""
    ids = [r.id for r in rows]
    return [p for p in study.kinds if not any(i == p or fnmatch.fnmatchcase(i, p) for i in ids)]


def tally(rows: Sequence[Row], arm: str | None = None) -> dict[str, int]:
    """Physics rows (of ``arm``, or all) by verdict: ``n``, ``agree``, ``disagree``,
    ``inconclusive``. Input, definition and info rows are never counted."""
    phys = [r for r in rows if r.kind == "physics" and (arm is None or r.arm == arm)]
    return {"n": len(phys), "agree": sum(r.verdict == "agrees" for r in phys),
            "disagree": sum(r.verdict == "disagrees" for r in phys),
            "inconclusive": sum(r.verdict == "inconclusive" for r in phys)}


def tally_line(rows: Sequence[Row]) -> str:
    """The report's first line: 'k of n physics rows agree, m disagree, j inconclusive (arm
    ...)', one clause per arm present; the rows not counted are named by kind."""
    arms = [a for a in ARMS if any(r.kind == "physics" and r.arm == a for r in rows)] or ["paper-model"]
    parts = []
    for a in arms:
        t = tally(rows, a)
        parts.append(f"{t['agree']} of {t['n']} physics rows agree, {t['disagree']} disagree, "
                     f"{t['inconclusive']} inconclusive (arm {a})")
    rest = {k: sum(r.kind == k for r in rows) for k in KINDS[1:]}
    return ("**" + "; ".join(parts) + "**; not counted: " + ", ".join(f"{v} {k}" for k, v in rest.items())
            + " rows")


# ------------------------------------------------------------------------------ code version
_PKG_ROOT = Path(__file__).resolve().parents[1]  # the mitpiv package folder
#: modules whose changes do not change a point's result: the frame (writer, report) itself
_NOT_POINT_CODE = frozenset({"mitpiv.replications.frame", "mitpiv.replications", "mitpiv.cli"})


def _module_file(name: str) -> Path | None:
    if name != "mitpiv" and not name.startswith("mitpiv."):
        return None
    rel = Path(*name.split(".")[1:]) if name != "mitpiv" else Path()
    for f in (_PKG_ROOT / rel.with_suffix(".py") if name != "mitpiv" else None, _PKG_ROOT / rel / "__init__.py"):
        if f is not None and f.is_file():
            return f
    return None


def _imports_of(name: str, f: Path) -> set[str]:
    """The mitpiv modules ``f`` imports anywhere (module level or inside functions), with
    their parent packages."""
    import ast

    pkg = name if f.name == "__init__.py" else name.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(ast.parse(f.read_text(encoding="utf-8"), filename=str(f))):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = pkg.split(".")[: len(pkg.split(".")) - (node.level - 1)]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            found.add(mod)
            found.update(f"{mod}.{a.name}" for a in node.names)  # a submodule, when it is one
    out = set()
    for m in found:
        parts = m.split(".")
        out.update(".".join(parts[:i]) for i in range(1, len(parts) + 1))
    return {m for m in out if _module_file(m) is not None}


def _dynamic_imports(name: str, f: Path) -> set[str]:
    """Modules ``name`` imports by name at run time, which the static closure cannot see: the
    Mitsuba plugins that :mod:`mitpiv.render.plugins` loads with ``importlib`` (every module
    of that package)."""
    if name != "mitpiv.render.plugins":
        return set()
    return {f"{name}.{p.stem}" for p in f.parent.glob("*.py") if p.name != "__init__.py"}


def code_modules(module: str) -> list[str]:
    """The mitpiv modules a study's points run: the static import closure of ``module``
    (every ``import`` in the source, also inside functions), with the Mitsuba plugins a
    render loads (:func:`_dynamic_imports`) and their imports, without the frame itself."""
    seen: set[str] = set()
    todo = [module]
    while todo:
        m = todo.pop()
        if m in seen or m in _NOT_POINT_CODE:
            continue
        f = _module_file(m)
        if f is None:
            continue
        seen.add(m)
        todo.extend((_imports_of(m, f) | _dynamic_imports(m, f)) - seen)
    return sorted(seen)


def code_hash(module: str) -> str:
    """A content hash (16 hex digits) of the mitpiv version and the source of every module
    :func:`code_modules` finds: a cached point computed by other code has another hash."""
    import hashlib

    from mitpiv.version import __version__

    h = hashlib.sha256(f"mitpiv {__version__}\n".encode())
    for m in code_modules(module):
        h.update(f"{m}\n".encode())
        h.update(_module_file(m).read_bytes())
    return h.hexdigest()[:16]


# ------------------------------------------------------------------------------ context
def _point_record(result, meta: dict) -> dict:
    return {"_point": dict(meta), "result": result}


def _run_point(fn, item, path: str, meta: dict):
    """Run ``fn(item)`` and store its JSON result at ``path`` with the code version and commit
    that computed it (a Dask task or a local call)."""
    from mitpiv._alloc import retain_freed_memory
    from mitpiv.io.records import write_json

    retain_freed_memory()  # this process (a worker, or the main one) reuses freed pages: mitpiv._alloc
    result = fn(item)
    write_json(path, _point_record(result, meta))
    return result


@dataclass
class ReplicationContext:
    """What a study's ``run`` sees: the scale, the seed and where to write, with resumable
    points (:meth:`cached`, :meth:`map`), experiment runs (:meth:`run`) and figures.

    Every stored point carries the code version that computed it (``code_hash``, the
    commit): a point stored by other code is computed again, never read back.
    """

    name: str
    out: Path
    quick: bool = False
    seed: int = 0
    workers: int = 1
    progress: Progress = None
    #: the content hash of the study's code (:func:`code_hash`) and the commit running it
    code_hash: str = ""
    commit: str = ""
    #: points computed by this invocation and points read back from an earlier run's cache
    n_computed: int = 0
    n_cached: int = 0
    #: cache key -> the commit that computed it, for the points read back
    cached_commits: dict = field(default_factory=dict)
    #: points stored by other code, computed again
    n_stale: int = 0

    @property
    def work(self) -> Path:
        """Intermediates: run folders and cached points (not committed)."""
        return self.out / "work"

    def _cache_file(self, key: str) -> Path:
        if not key or any(c in key for c in "/\\") or key.startswith("."):
            raise ConfigError(f"replication {self.name}: cache key {key!r} must be a non-empty file name "
                              "without '/' or a leading dot (e.g. 'D1_SA0.1_rho2').")
        return self.work / "cache" / f"{key}.json"

    def _meta(self, key: str) -> dict:
        from mitpiv.version import __version__

        return {"key": key, "code_hash": self.code_hash, "commit": self.commit, "mitpiv_version": __version__}

    def _read_point(self, key: str, f: Path):
        """The stored result of ``key`` when it was computed by this code, else None (a stale or
        an old-format file is computed again)."""
        from mitpiv.io.records import read_json

        if not f.is_file():
            return None
        rec = read_json(f)
        meta = rec.get("_point") if isinstance(rec, dict) else None
        if not isinstance(meta, dict) or meta.get("code_hash") != self.code_hash or "result" not in rec:
            self.n_stale += 1
            log.info("replication %s: point %s was computed by other code (%s); computing it again", self.name, key,
                     meta.get("commit") if isinstance(meta, dict) else "no code version")
            return None
        self.cached_commits[key] = meta.get("commit", "")
        return rec

    def cached(self, key: str, fn: Callable[[], dict]) -> dict:
        """``fn()`` run once and its JSON-ready result stored under ``key``; a rerun (a resume
        after a kill) reads the stored result back instead of running ``fn`` again, when the
        same code computed it."""
        from mitpiv.io.records import read_json, write_json

        f = self._cache_file(key)
        rec = self._read_point(key, f)
        if rec is not None:
            self.n_cached += 1
            return rec["result"]
        self.n_computed += 1
        self.cached_commits.pop(key, None)
        write_json(f, _point_record(fn(), self._meta(key)))
        return read_json(f)["result"]

    def map(self, fn: Callable[[Any], dict], items: Sequence, key: Callable[[Any], str], *,
            desc: str = "points") -> list[dict]:
        """``[fn(item) for item in items]`` with each result cached under ``key(item)``; points
        already cached by the same code are not run again. With ``workers > 1`` the remaining
        points run on a local Dask cluster of single-threaded processes (``fn`` and the items
        must pickle: a module-level function)."""
        from mitpiv.io.records import read_json

        keys = [key(it) for it in items]
        if len(set(keys)) != len(keys):
            dup = sorted({k for k in keys if keys.count(k) > 1})
            raise ConfigError(f"replication {self.name}: map keys must be unique per item; repeated: {dup[:5]}.")
        files = [self._cache_file(k) for k in keys]
        done = {i for i, (k, f) in enumerate(zip(keys, files, strict=True)) if self._read_point(k, f) is not None}
        todo = [i for i in range(len(items)) if i not in done]
        self.n_cached += len(done)
        self.n_computed += len(todo)
        log.info("replication %s: %s: %d points, %d done earlier", self.name, desc, len(items), len(done))
        with bar(len(todo), desc=f"{self.name}: {desc}", progress=self.progress, unit="point") as b:
            if self.workers > 1 and len(todo) > 1:
                from dask.distributed import Client, LocalCluster, as_completed

                with LocalCluster(n_workers=self.workers, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, Client(cluster) as client:
                    futs = {client.submit(_run_point, fn, items[i], str(files[i]), self._meta(keys[i]), pure=False,
                                          retries=1): i for i in todo}
                    for fut in as_completed(futs):
                        fut.result()
                        b.update()
            else:
                for i in todo:
                    _run_point(fn, items[i], str(files[i]), self._meta(keys[i]))
                    b.update()
        # read back every result as JSON types, the same whether it ran now or earlier
        return [read_json(f)["result"] for f in files]

    def run(self, name: str, experiment, overrides: dict | None = None, *, until: str | None = None):
        """Run (or resume) an experiment (a TOML path or a validated model) into
        ``work/runs/<code hash>/<name>`` with the experiment runner (its stages resume only
        within one code version); returns its RunResult."""
        from pydantic import BaseModel

        from mitpiv.studies.runner import load_experiment, run_config

        cfg = experiment if isinstance(experiment, BaseModel) else load_experiment(experiment, overrides)
        if isinstance(experiment, BaseModel) and overrides:
            raise ConfigError(f"replication {self.name}: overrides apply to a TOML path; apply them before "
                              "validating the model.")
        return run_config(cfg, self.work / "runs" / (self.code_hash or "nohash") / name, until=until,
                          progress=self.progress)

    def figure(self, fig, filename: str) -> str:
        """Save a matplotlib figure as ``filename`` (PNG) in the output folder; returns the name
        to list in :attr:`ReplicationResult.figures`."""
        from mitpiv.io.figures import save_figure

        if not filename.endswith(".png") or "/" in filename:
            raise ConfigError(f"replication {self.name}: figure name {filename!r} must be a plain .png file name.")
        save_figure(fig, self.out / filename)
        return filename


# ------------------------------------------------------------------------------ registry
def _registry() -> dict[str, str]:
    from mitpiv.replications import MODULES

    return MODULES


def list_studies() -> list[str]:
    """The names of the registered replications."""
    return sorted(_registry())


def get_study(name: str) -> Study:
    """The registered replication ``name`` (its module is imported on first use)."""
    import difflib

    reg = _registry()
    if name not in reg:
        near = difflib.get_close_matches(name, list(reg), n=1, cutoff=0.5)
        hint = f" Did you mean {near[0]!r}?" if near else ""
        raise ConfigError(f"replicate: no study named {name!r}.{hint} Known studies: {sorted(reg)} "
                          "(`mitpiv replicate --list`).")
    study = importlib.import_module(reg[name]).STUDY
    if study.name != name:
        raise ConfigError(f"replication module {reg[name]} defines study {study.name!r}, registered as {name!r}.")
    return study


# ------------------------------------------------------------------------------ writing
def _commit() -> str:
    """The git commit of the mitpiv source tree (with '+dirty' for uncommitted changes), or
    the package version when mitpiv is not run from a git checkout."""
    from mitpiv.version import __version__

    root = Path(__file__).resolve().parents[2]
    try:
        rev = subprocess.run(["git", "-C", str(root), "rev-parse", "--short=12", "HEAD"], capture_output=True,
                             text=True, timeout=10, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no", "mitpiv"],
                               capture_output=True, text=True, timeout=10, check=True).stdout.strip()
        return rev + ("+dirty" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        return f"mitpiv {__version__} (no git checkout)"


def _fmt(v, unit: str = "") -> str:
    if v is None:
        return "–"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        s = f"{v:.4g}"
    else:
        s = str(v)
    return s + (f" {unit}" if unit and not isinstance(v, str) else "")


def _cells(cells) -> str:
    return "| " + " | ".join(str(c).replace("|", "\\|").replace("\n", " ") for c in cells) + " |"


_SHOWN_VERDICT = {"agrees": "yes", "disagrees": "**no**", "inconclusive": "inconclusive", "not compared": "–"}


def _note(r: Row) -> str:
    return "; ".join(s for s in (r.note, (f"caveat: {r.why}" if r.kind == "physics" and r.why else "")) if s)


def _table(rows: Sequence[Row]) -> str:
    """The counted rows: physics rows of every arm, their interval and verdict, every note."""
    lines = ["| id | quantity | arm | paper source | paper | ours | 95 % interval (n) | tolerance | agrees | note |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        ci = (f"[{_fmt(r.ci[0])}, {_fmt(r.ci[1])}] ({r.n}, {r.ci_method})" if r.ci is not None
              else f"– (n = {r.n})")
        lines.append(_cells([f"`{r.id}`", r.quantity, r.arm, r.paper_source, _fmt(r.paper, r.unit),
                             _fmt(r.ours, r.unit), ci, r.tolerance, _SHOWN_VERDICT[r.verdict], _note(r)]))
    return "\n".join(lines)


def _table_apart(rows: Sequence[Row]) -> str:
    """The rows not counted (input, definition, info): why each is not a prediction."""
    lines = ["| id | kind | quantity | paper source | paper | ours | matches the paper | why not counted | note |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(_cells([f"`{r.id}`", r.kind, r.quantity, r.paper_source, _fmt(r.paper, r.unit),
                             _fmt(r.ours, r.unit), _SHOWN_VERDICT[r.verdict], r.why, r.note]))
    return "\n".join(lines)


def check_rows(study: Study, rows: Sequence[Row]) -> None:
    """Refuse rows that break the results contract: duplicate ids, a missing required id, or
    something that is not a :class:`Row`."""
    bad = [r for r in rows if not isinstance(r, Row)]
    if bad:
        raise ConfigError(f"replication {study.name}: rows must be Row objects, got {type(bad[0]).__name__}.")
    ids = [r.id for r in rows]
    dups = sorted({i for i in ids if ids.count(i) > 1})
    if dups:
        raise ConfigError(f"replication {study.name}: duplicate row ids {dups}.")
    missing = [i for i in study.required_ids if i not in ids]
    if missing:
        raise ConfigError(f"replication {study.name}: required row ids missing: {missing}.")


_SECTIONS_BEGIN, _SECTIONS_END = "<!-- study sections -->", "<!-- /study sections -->"


def _report(study: Study, rows: Sequence[Row], header: list[str], sections: Sequence[str],
            figures: Sequence[str]) -> str:
    """report.md: the generated tally as its first line, the header, the counted rows, the
    rows apart, the study's sections and its figures."""
    phys = [r for r in rows if r.kind == "physics"]
    apart = [r for r in rows if r.kind != "physics"]
    no_ci = sum(1 for r in phys if r.ci is None)
    if no_ci:
        header = [*header, f"- Intervals: {no_ci} of {len(phys)} physics rows rest on one realisation and have no "
                           "interval; their verdicts compare a point with the paper's band (REPLICATION.md, point 9)."]
    md = [tally_line(rows), "", f"# Replication: {study.title}", "", *header, "",
          "## Paper vs ours: physics rows (counted)", "",
          "Only physics rows, predictions from inputs that do not contain the paper's answer, are counted "
          "(REPLICATION.md, point 7). A row agrees when its 95 % interval over independent realisations meets "
          "the paper's band, is inconclusive when the interval straddles the band's edge and is wider than the "
          "band, and is judged as a point where there is one realisation (n = 1).", "",
          _table(phys) if phys else "No physics rows.", ""]
    if apart:
        md += ["## Rows not counted: inputs, definitions, context", "",
               "Inputs were set from a result the paper reports; definitions are true by construction or arithmetic "
               "on the paper's numbers; info rows are shown for context. Their agreement says nothing about the "
               "simulation.", ""]
        if study.inputs_from_paper:
            md += ["The study's inputs taken from the paper's results:", ""]
            md += [f"- `{k}`: {v}" for k, v in study.inputs_from_paper.items()] + [""]
        md += [_table_apart(apart), ""]
    md += [_SECTIONS_BEGIN]
    for s in sections:
        md += [s.rstrip(), ""]
    md += [_SECTIONS_END, ""]
    if figures:
        md += ["## Figures", ""]
        md += [f"![{f}]({f})\n" for f in figures]
    return "\n".join(md)


def _points_line(computed: int, cached: int, commits: dict, commit: str) -> str:
    if not cached:
        return f"{computed} points computed by this run"
    by = {}
    for c in commits.values():
        by[c] = by.get(c, 0) + 1
    return (f"{computed} points computed by this run, {cached} read back from the cache (computed by "
            + ", ".join(f"{n} at `{c}`" for c, n in sorted(by.items())) + ")")


def write_outputs(study: Study, ctx: ReplicationContext, result: ReplicationResult, *, wall_s: float,
                  command: str, allow_mixed: bool = False) -> dict:
    """Write ``results.json`` and ``report.md`` into ``ctx.out``; returns the results dict.

    The study's kinds are applied and checked (:func:`classify_rows`). Full-scale results
    whose cached points were computed by another commit are refused unless ``allow_mixed``
    (then the report's header says so): a committed full result is one code version.
    """
    from mitpiv.io.records import to_jsonable, write_json, write_text
    from mitpiv.version import __version__

    check_rows(study, result.rows)
    rows = classify_rows(study, result.rows)
    missing_fig = [f for f in result.figures if not (ctx.out / f).is_file()]
    if missing_fig:
        raise ConfigError(f"replication {study.name}: figures listed but not written: {missing_fig}.")
    scale = "quick" if ctx.quick else "full"
    commit = ctx.commit or _commit()
    other = sorted({c for c in ctx.cached_commits.values() if c != commit})
    if other and scale == "full" and not allow_mixed:
        raise ConfigError(f"replication {study.name}: {sum(c != commit for c in ctx.cached_commits.values())} "
                          f"cached point(s) were computed at commit(s) {other}, this run is at {commit}: a full "
                          "result is one code version (REPLICATION.md, point 12). Recompute them (delete the "
                          "output folder's work/cache, or run from a clean commit), or pass --allow-mixed to write "
                          "the results with the mixture stated in the report.")
    results = {
        "study": study.name, "title": study.title, "paper": study.paper, "scale": scale, "commit": commit,
        "mitpiv_version": __version__, "code_hash": ctx.code_hash, "command": command, "wall_s": round(float(wall_s), 1),
        "tally": {a: tally(rows, a) for a in ARMS},
        "points_computed": ctx.n_computed, "points_cached": ctx.n_cached,
        "cached_point_commits": dict(sorted(ctx.cached_commits.items())), "mixed_commits": bool(other),
        "inputs_from_paper": dict(study.inputs_from_paper),
        "rows": [asdict(r) for r in rows],
        "curves": {k: (c.to_dict() if isinstance(c, Curve) else c) for k, c in result.curves.items()},
        "figures": list(result.figures),
    }
    results = to_jsonable(results)
    json.dumps(results, allow_nan=False)  # NaN is not a result: rows carry null instead
    header = [f"- Study: `{study.name}`; paper: `{study.paper}` (in the project's shared seeds folder)",
              f"- Command: `{command}`",
              f"- Scale: {scale}; wall time {wall_s:.0f} s on {_machine()}; commit `{commit}`, code `{ctx.code_hash}`; "
              + _points_line(ctx.n_computed, ctx.n_cached, ctx.cached_commits, commit)]
    if other:
        header.append(f"- **Mixed code versions** (--allow-mixed): cached points from commit(s) "
                      f"{', '.join(f'`{c}`' for c in other)} beside this run's `{commit}`.")
    write_json(ctx.out / "results.json", results)
    write_text(ctx.out / "report.md", _report(study, rows, header, result.sections, result.figures))
    return results


def _machine() -> str:
    import os
    import platform

    return f"{os.cpu_count()} cores, {platform.machine()}, Python {platform.python_version()}"


def _old_sections(md: str) -> tuple[list[str], list[str]]:
    """The study's own sections and figures of a report.md this writer made (between its
    markers), or of one made before the markers (after the rows' table, before Figures)."""
    import re

    figures = re.findall(r"^!\[[^\]]*\]\(([^)]+\.png)\)", md, flags=re.M)
    if _SECTIONS_BEGIN in md and _SECTIONS_END in md:
        body = md.split(_SECTIONS_BEGIN, 1)[1].split(_SECTIONS_END, 1)[0]
    else:
        lines = md.splitlines()
        try:
            i = next(k for k, ln in enumerate(lines) if ln.startswith("## Paper vs ours"))
        except StopIteration:
            raise ConfigError("reclassify: report.md has no '## Paper vs ours' table; regenerate the study "
                              "instead.") from None
        i += 1
        while i < len(lines) and (not lines[i].strip() or lines[i].startswith("|")):
            i += 1
        rest = "\n".join(lines[i:])
        body = rest.split("\n## Figures", 1)[0]
    return [body.strip()] if body.strip() else [], figures


def reclassify(name: str, out) -> dict:
    """Apply the study's current kinds (:attr:`Study.kinds`) to the results already in ``out``
    (results.json and report.md of an earlier run) and write both again, without
    recomputing a point: the rows' numbers, the curves, the figures and the study's sections
    stay as they were, and the header says which commit computed them and which classified
    them."""
    from mitpiv.io.records import read_json, to_jsonable, write_json, write_text

    study = get_study(name)
    out = Path(out)
    f = out / "results.json"
    if not f.is_file() or not (out / "report.md").is_file():
        raise ConfigError(f"reclassify: {str(out)!r} has no results.json and report.md of an earlier run of "
                          f"{name}; run `mitpiv replicate {name} --out {out}` first.")
    old = read_json(f)
    if old.get("study") != name:
        raise ConfigError(f"reclassify: {str(f)!r} holds study {old.get('study')!r}, not {name!r}.")
    derived = {"kind", "why", "reads"}  # from the study's declarations
    rows = [Row.from_dict({k: v for k, v in r.items() if k not in derived}) for r in old["rows"]]
    check_rows(study, rows)
    rows = classify_rows(study, rows)
    stale = unused_kinds(study, rows)
    if stale:
        raise ConfigError(f"reclassify {name}: the study declares kinds for ids no row has: {stale}.")
    sections, figures = _old_sections((out / "report.md").read_text(encoding="utf-8"))
    computed_by = old.get("computed_by", old.get("commit"))
    now = _commit()
    pts = old.get("points") or {"computed": old.get("points_computed"), "from_cache": old.get("points_cached")}
    results = dict(old)
    results.update({"commit": computed_by, "classified_by": now, "computed_by": computed_by,
                    "tally": {a: tally(rows, a) for a in ARMS}, "inputs_from_paper": dict(study.inputs_from_paper),
                    "rows": [asdict(r) for r in rows], "figures": old.get("figures", figures)})
    results = to_jsonable(results)
    json.dumps(results, allow_nan=False)
    header = [f"- Study: `{study.name}`; paper: `{study.paper}` (in the project's shared seeds folder)",
              f"- Command: `{old.get('command')}`; rows reclassified by `mitpiv replicate {name} --reclassify --out "
              f"{out}` at commit `{now}` (no point recomputed)",
              f"- Scale: {old.get('scale')}; wall time {float(old.get('wall_s', 0)):.0f} s; rows computed at commit "
              f"`{computed_by}` ({pts.get('computed')} points computed by that run, {pts.get('from_cache')} read back "
              "from caches of earlier commits, which those caches did not record: one code version is not "
              "established for these numbers)"]
    write_json(f, results)
    write_text(out / "report.md", _report(study, rows, header, sections, results["figures"]))
    return results


# ------------------------------------------------------------------------------ entry point
def replicate(name: str, out=None, *, quick: bool = False, seed: int = 0, workers: int = 1,
              progress: Progress = None, allow_mixed: bool = False) -> dict:
    """Run (or resume) the replication ``name`` into ``out`` (default
    ``out/replicate/NAME`` or ``...-quick``); returns the results written to results.json.
    ``allow_mixed`` lets full-scale results use cached points of other commits (stated in
    the report); points stored by other code are always computed again."""
    study = get_study(name)
    if not isinstance(seed, int) or isinstance(seed, bool) or not 0 <= seed < 2**32:
        raise ConfigError(f"replicate: seed must be an integer in [0, 2**32), got {seed!r}.")
    if not isinstance(workers, int) or isinstance(workers, bool) or workers < 1:
        raise ConfigError(f"replicate: workers must be an integer >= 1, got {workers!r}.")
    out = Path(out) if out is not None else Path("out") / "replicate" / (name + ("-quick" if quick else ""))
    if out.exists() and not out.is_dir():
        raise ConfigError(f"replicate: --out {str(out)!r} is a file; give a folder for the results.")
    out.mkdir(parents=True, exist_ok=True)
    ctx = ReplicationContext(name=name, out=out, quick=quick, seed=seed, workers=workers, progress=progress,
                             code_hash=code_hash(_registry()[name]),
                             commit=_commit())
    command = " ".join(["mitpiv", "replicate", name] + (["--quick"] if quick else []) + ["--out", str(out)]
                       + ([f"--seed {seed}"] if seed else []) + (["--allow-mixed"] if allow_mixed else []))
    log.info("replication %s (%s) -> %s", name, "quick" if quick else "full", out)
    t0 = time.perf_counter()
    result = study.run(ctx)
    if not isinstance(result, ReplicationResult):
        raise ConfigError(f"replication {name}: run() must return a ReplicationResult, got {type(result).__name__}.")
    return write_outputs(study, ctx, result, wall_s=time.perf_counter() - t0, command=command,
                         allow_mixed=allow_mixed)


if __name__ == "__main__":  # pragma: no cover
    sys.exit("use: mitpiv replicate NAME [--quick]")
