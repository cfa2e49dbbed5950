"""Replications of the published studies mitpiv was designed from (``mitpiv replicate NAME``).

The standard every replication follows is the project's REPLICATION.md: the paper's set-up,
the paper's measures by the paper's definitions, every sweep axis the paper has, the
headline results side by side with ours, and every disagreement investigated. This module is
the frame they share; each study is a module of :mod:`mitpiv.studies.replications` that
defines ``STUDY = Study(...)`` with a ``run(ctx) -> ReplicationResult`` function.

A replication run writes into its output folder:

- ``results.json``: ``{"study", "title", "paper", "scale": "full"|"quick", "commit",
  "mitpiv_version", "command", "wall_s", "rows": [...], "curves": {...}}``, one row per
  compared quantity (:class:`Row`: id, quantity, paper_source, paper, ours, unit, tolerance,
  agrees, note) and every swept series as a :class:`Curve`;
- ``report.md``: the table, the study's own sections (method, crops, disagreements and their
  causes) and its figures (PNG files beside it);
- ``work/``: intermediates (run folders, cached point results). A rerun resumes from them:
  every expensive point goes through :meth:`ReplicationContext.cached` or
  :meth:`ReplicationContext.map`, which store each point's JSON result once it is complete.

The quick scale (``--quick``) runs the same code with the same row ids on a reduced problem
(minutes on 2 cores); the tests run it. Both scales are written by the same writer, which
refuses duplicate ids and a missing required id.
"""

from __future__ import annotations

import importlib
import json
import logging
import math
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from mitpiv.errors import ConfigError
from mitpiv.progress import Progress, bar

__all__ = ["Row", "Curve", "Study", "ReplicationContext", "ReplicationResult", "compare_value", "compare_trend",
           "replicate", "get_study", "list_studies", "write_outputs", "RESULTS_KEYS"]

log = logging.getLogger(__name__)

#: Top-level keys of results.json (REPLICATION.md, point 5).
RESULTS_KEYS = ("study", "title", "paper", "scale", "commit", "mitpiv_version", "command", "wall_s", "rows", "curves")


# ------------------------------------------------------------------------------ rows and curves
@dataclass(frozen=True)
class Row:
    """One compared quantity of a replication.

    id : a stable name other tools read (``Q_D0``, ``ltpr_cross_nc4``).
    quantity : what it is, in words.
    paper_source : where it is in the paper (``Fig. 4-1``, ``Table 1``).
    paper, ours : the paper's value or trend, and ours (numbers, or text for a trend).
    unit : the unit of ``paper`` and ``ours`` ("" for dimensionless).
    tolerance : the tolerance we hold ourselves to, and why (in words).
    agrees : whether ours agrees with the paper within the tolerance (None: the paper gives
        no comparable value, e.g. a quantity we add).
    note : the cause of a disagreement, a caveat or a crop.
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


def _finite_or_none(v):
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def compare_value(id: str, quantity: str, paper_source: str, paper: float, ours: float, *, unit: str = "",
                  rel: float | None = None, abs: float | None = None, note: str = "",
                  why: str = "") -> Row:
    """A numeric row: ``agrees = |ours - paper| <= max(abs, rel * |paper|)``.

    rel, abs : the relative and absolute tolerances (at least one). ``why`` says where the
        tolerance comes from (sampling error, the paper's reading precision, ...); it is
        appended to the tolerance text.
    A non-finite ``ours`` never agrees (and is written as null).
    """
    if rel is None and abs is None:
        raise ConfigError(f"compare_value({id!r}): give a tolerance, rel= or abs= (e.g. rel=0.1 for 10 %).")
    ours_f = float(ours) if ours is not None else float("nan")
    paper_f = float(paper)
    tol = max(abs or 0.0, (rel or 0.0) * math.fabs(paper_f))
    agrees = bool(math.isfinite(ours_f) and math.fabs(ours_f - paper_f) <= tol)
    parts = []
    if rel is not None:
        parts.append(f"±{rel * 100:g} %")
    if abs is not None:
        parts.append(f"±{abs:g}{(' ' + unit) if unit else ''}")
    text = " or ".join(parts) + (f" ({why})" if why else "")
    return Row(id=id, quantity=quantity, paper_source=paper_source, paper=paper_f,
               ours=_finite_or_none(ours_f), unit=unit, tolerance=text, agrees=agrees, note=note)


def compare_trend(id: str, quantity: str, paper_source: str, paper: str, ours, agrees: bool, *,
                  unit: str = "", tolerance: str = "", note: str = "") -> Row:
    """A trend row (a sign, an ordering, a crossing): the study's code decides ``agrees``."""
    return Row(id=id, quantity=quantity, paper_source=paper_source, paper=paper,
               ours=_finite_or_none(ours), unit=unit, tolerance=tolerance, agrees=bool(agrees), note=note)


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
    ``run(ctx)`` function and the row ids every run (full or quick) must produce."""

    name: str
    paper: str
    title: str
    run: Callable[[ReplicationContext], ReplicationResult]
    required_ids: tuple[str, ...] = ()
    describe: str = ""


# ------------------------------------------------------------------------------ context
def _run_point(fn, item, path: str):
    """Run ``fn(item)`` and store its JSON result at ``path`` (a Dask task or a local call)."""
    from mitpiv._alloc import retain_freed_memory
    from mitpiv.io.records import write_json

    retain_freed_memory()  # this process (a worker, or the main one) reuses freed pages: mitpiv._alloc
    result = fn(item)
    write_json(path, result)
    return result


@dataclass
class ReplicationContext:
    """What a study's ``run`` sees: the scale, the seed and where to write, with resumable
    points (:meth:`cached`, :meth:`map`), experiment runs (:meth:`run`) and figures."""

    name: str
    out: Path
    quick: bool = False
    seed: int = 0
    workers: int = 1
    progress: Progress = None
    #: points computed by this invocation and points read back from an earlier run's cache
    n_computed: int = 0
    n_cached: int = 0

    @property
    def work(self) -> Path:
        """Intermediates: run folders and cached points (not committed)."""
        return self.out / "work"

    def _cache_file(self, key: str) -> Path:
        if not key or any(c in key for c in "/\\") or key.startswith("."):
            raise ConfigError(f"replication {self.name}: cache key {key!r} must be a non-empty file name "
                              "without '/' or a leading dot (e.g. 'D1_SA0.1_rho2').")
        return self.work / "cache" / f"{key}.json"

    def cached(self, key: str, fn: Callable[[], dict]) -> dict:
        """``fn()`` run once and its JSON-ready result stored under ``key``; a rerun (a resume
        after a kill) reads the stored result back instead of running ``fn`` again."""
        from mitpiv.io.records import read_json, write_json

        f = self._cache_file(key)
        if f.is_file():
            self.n_cached += 1
            return read_json(f)
        self.n_computed += 1
        result = fn()
        write_json(f, result)
        return read_json(f)

    def map(self, fn: Callable[[Any], dict], items: Sequence, key: Callable[[Any], str], *,
            desc: str = "points") -> list[dict]:
        """``[fn(item) for item in items]`` with each result cached under ``key(item)``; points
        already cached are not run again. With ``workers > 1`` the remaining points run on a
        local Dask cluster of single-threaded processes (``fn`` and the items must pickle: a
        module-level function)."""
        from mitpiv.io.records import read_json

        keys = [key(it) for it in items]
        if len(set(keys)) != len(keys):
            dup = sorted({k for k in keys if keys.count(k) > 1})
            raise ConfigError(f"replication {self.name}: map keys must be unique per item; repeated: {dup[:5]}.")
        files = [self._cache_file(k) for k in keys]
        results: dict[int, dict] = {i: read_json(f) for i, f in enumerate(files) if f.is_file()}
        todo = [i for i in range(len(items)) if i not in results]
        self.n_cached += len(results)
        self.n_computed += len(todo)
        log.info("replication %s: %s: %d points, %d done earlier", self.name, desc, len(items), len(results))
        with bar(len(todo), desc=f"{self.name}: {desc}", progress=self.progress, unit="point") as b:
            if self.workers > 1 and len(todo) > 1:
                from dask.distributed import Client, LocalCluster, as_completed

                with LocalCluster(n_workers=self.workers, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, Client(cluster) as client:
                    futs = {client.submit(_run_point, fn, items[i], str(files[i]), pure=False, retries=1): i
                            for i in todo}
                    for fut in as_completed(futs):
                        results[futs[fut]] = fut.result()
                        b.update()
            else:
                for i in todo:
                    results[i] = _run_point(fn, items[i], str(files[i]))
                    b.update()
        # read back every result as JSON types, the same whether it ran now or earlier
        return [read_json(f) for f in files]

    def run(self, name: str, experiment, overrides: dict | None = None, *, until: str | None = None):
        """Run (or resume) an experiment (a TOML path or a validated model) into
        ``work/runs/<name>`` with the experiment runner; returns its RunResult."""
        from pydantic import BaseModel

        from mitpiv.studies.runner import load_experiment, run_config

        cfg = experiment if isinstance(experiment, BaseModel) else load_experiment(experiment, overrides)
        if isinstance(experiment, BaseModel) and overrides:
            raise ConfigError(f"replication {self.name}: overrides apply to a TOML path; apply them before "
                              "validating the model.")
        return run_config(cfg, self.work / "runs" / name, until=until, progress=self.progress)

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
    from mitpiv.studies.replications import MODULES

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


def _table(rows: Sequence[Row]) -> str:
    head = "| id | quantity | paper source | paper | ours | tolerance | agrees | note |\n|---|---|---|---|---|---|---|---|"
    lines = [head]
    for r in rows:
        ag = "–" if r.agrees is None else ("yes" if r.agrees else "**no**")
        cells = [f"`{r.id}`", r.quantity, r.paper_source, _fmt(r.paper, r.unit), _fmt(r.ours, r.unit), r.tolerance,
                 ag, r.note]
        lines.append("| " + " | ".join(str(c).replace("|", "\\|").replace("\n", " ") for c in cells) + " |")
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


def write_outputs(study: Study, ctx: ReplicationContext, result: ReplicationResult, *, wall_s: float,
                  command: str) -> dict:
    """Write ``results.json`` and ``report.md`` into ``ctx.out``; returns the results dict."""
    from mitpiv.io.records import to_jsonable, write_json, write_text
    from mitpiv.version import __version__

    check_rows(study, result.rows)
    missing_fig = [f for f in result.figures if not (ctx.out / f).is_file()]
    if missing_fig:
        raise ConfigError(f"replication {study.name}: figures listed but not written: {missing_fig}.")
    scale = "quick" if ctx.quick else "full"
    results = {
        "study": study.name, "title": study.title, "paper": study.paper, "scale": scale, "commit": _commit(),
        "mitpiv_version": __version__, "command": command, "wall_s": round(float(wall_s), 1),
        "points": {"computed": ctx.n_computed, "from_cache": ctx.n_cached},
        "rows": [asdict(r) for r in result.rows],
        "curves": {k: (c.to_dict() if isinstance(c, Curve) else c) for k, c in result.curves.items()},
    }
    results = to_jsonable(results)
    json.dumps(results, allow_nan=False)  # NaN is not a result: rows carry null instead
    write_json(ctx.out / "results.json", results)
    n_ok = sum(1 for r in result.rows if r.agrees is True)
    n_cmp = sum(1 for r in result.rows if r.agrees is not None)
    md = [f"# Replication: {study.title}", "",
          f"- Study: `{study.name}`; paper: `{study.paper}` (in the project's shared seeds folder)",
          f"- Command: `{command}`",
          f"- Scale: {scale}; wall time {wall_s:.0f} s on {_machine()}; commit `{results['commit']}`"
          + (f" ({ctx.n_computed} points computed by this run, {ctx.n_cached} read back from the cache of earlier "
             "runs of the same command)" if ctx.n_cached else ""),
          f"- Agreement: {n_ok} of {n_cmp} compared rows agree within their tolerance", "",
          "## Paper vs ours", "", _table(result.rows), ""]
    for s in result.sections:
        md += [s.rstrip(), ""]
    if result.figures:
        md += ["## Figures", ""]
        md += [f"![{f}]({f})\n" for f in result.figures]
    write_text(ctx.out / "report.md", "\n".join(md))
    return results


def _machine() -> str:
    import os
    import platform

    return f"{os.cpu_count()} cores, {platform.machine()}, Python {platform.python_version()}"


# ------------------------------------------------------------------------------ entry point
def replicate(name: str, out=None, *, quick: bool = False, seed: int = 0, workers: int = 1,
              progress: Progress = None) -> dict:
    """Run (or resume) the replication ``name`` into ``out`` (default
    ``out/replicate/NAME`` or ``...-quick``); returns the results written to results.json."""
    study = get_study(name)
    if not isinstance(seed, int) or isinstance(seed, bool) or not 0 <= seed < 2**32:
        raise ConfigError(f"replicate: seed must be an integer in [0, 2**32), got {seed!r}.")
    if not isinstance(workers, int) or isinstance(workers, bool) or workers < 1:
        raise ConfigError(f"replicate: workers must be an integer >= 1, got {workers!r}.")
    out = Path(out) if out is not None else Path("out") / "replicate" / (name + ("-quick" if quick else ""))
    if out.exists() and not out.is_dir():
        raise ConfigError(f"replicate: --out {str(out)!r} is a file; give a folder for the results.")
    out.mkdir(parents=True, exist_ok=True)
    ctx = ReplicationContext(name=name, out=out, quick=quick, seed=seed, workers=workers, progress=progress)
    command = " ".join(["mitpiv", "replicate", name] + (["--quick"] if quick else []) + ["--out", str(out)]
                       + ([f"--seed {seed}"] if seed else []))
    log.info("replication %s (%s) -> %s", name, "quick" if quick else "full", out)
    t0 = time.perf_counter()
    result = study.run(ctx)
    if not isinstance(result, ReplicationResult):
        raise ConfigError(f"replication {name}: run() must return a ReplicationResult, got {type(result).__name__}.")
    return write_outputs(study, ctx, result, wall_s=time.perf_counter() - t0, command=command)


if __name__ == "__main__":  # pragma: no cover
    sys.exit("use: mitpiv replicate NAME [--quick]")
