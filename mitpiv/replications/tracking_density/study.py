"""The tracking comparison study (issue 27, item 7): a ``mitpiv sweep`` of a tracking
experiment with ``[compare] openlpt = true, tomo = true`` over particles per pixel, turned into
``results.json`` (one row per method and density), ``report.md`` (the rows as a table) and one
figure per metric against ppp.

    mitpiv sweep scenes/tracking_lpt/study.toml --out out/tracking_ppp --tracking-results docs/studies/tracking

(``--tracking-results`` on a finished sweep folder reruns nothing and only writes the files.)

Rows (``results.json`` ``rows``; every metric is ``null`` with its reason in ``null_reasons``
where it has no value):

``method``
    ``mitpiv-stb`` (the track stage), ``openlpt-stb`` (the openlpt stage),
    ``mitpiv-tomo`` (the tomo stage); a method that was not run at a point has no row there.
``ppp``
    the swept ``seeding.ppp`` (the nominal density), else the measured one; ``ppp_measured``:
    particles in the box that the first camera sees, per pixel, at frame 0.
``yield``, ``ghost_fraction``, ``position_error_px``
    the LPT Challenge's definitions (:mod:`mitpiv.tracking.metrics`), the same match radius
    for both trackers; ``null`` for tomographic PIV, where they do not apply
    (:data:`~mitpiv.studies.kinds.tracking.compare.TOMO_NOT_APPLICABLE`).
``velocity_error``
    for all three methods on the same Eulerian grid (``[evaluate] bin_mm``): the RMS over the
    bins of the difference between the method's mean velocity and the binned truth's,
    divided by the RMS of the true bin means (``velocity_error_mm_s``: not divided);
    ``track_velocity_error``: the trackers' per-particle error relative to the RMS speed.
``acceleration_error``
    the trackers' per-particle acceleration error relative to the RMS true acceleration
    (:func:`~mitpiv.tracking.metrics.track_metrics`); ``null`` for tomographic PIV.
``wall_s``, ``wall_per_frame_s``
    seconds of the method's own work: mitpiv STB the otf and track stages; OpenLPT its run
    (without the export, ``export_s``); tomo its reconstructions and correlations. The
    render and calibrate stages that all three share are not counted. Per frame: divided by
    the sequence's frames (tomo: by the frames it reconstructed).
``seed``, ``frames``
    the swept ``seed`` (one independent particle field, flow realisation and sensor noise
    per seed; ``null`` when the sweep does not vary it) and the sequence's frames.
``status``, ``error``
    ``ok``, or ``failed`` with the exact reason (e.g. OpenLPT's exit status and log).

Summary (``results.json`` ``summary``; one entry per method and density): per metric the
mean over the seeds' ``ok`` rows that have a value, its Student-t 95 % interval
(``<metric>_ci``, ``null`` with fewer than two values; on log-scale figures a lower end at or
below 0 is not drawn), ``n`` the ``ok`` rows and ``failed`` the seeds whose row failed.
"""

from __future__ import annotations

import math
from pathlib import Path

from mitpiv.errors import FileFormatError

__all__ = ["study_rows", "study_summary", "write_tracking_study", "METRICS", "PUBLISHED_LIMITS"]

#: Published density limits drawn on the yield and ghost figures: (ppp, label, line style).
PUBLISHED_LIMITS = ((0.125, "STB ghost-free limit, Schanz et al. 2016 (0.125)", "--"),
                    (0.14, "IPR ghost-free limit, Jahn et al. 2021 (0.14)", ":"))

#: The metrics plotted against ppp: (column, axis label, log scale).
METRICS = (("yield", "yield", False), ("ghost_fraction", "ghost fraction", False),
           ("position_error_px", "position error [px]", True),
           ("velocity_error", "binned velocity error (of the RMS bin speed)", True),
           ("acceleration_error", "acceleration error (of the RMS acceleration)", True),
           ("wall_per_frame_s", "wall time per frame [s]", True))

#: The columns the summary averages over seeds.
SUMMARY_KEYS = ("yield", "ghost_fraction", "position_error_px", "velocity_error", "track_velocity_error",
                "acceleration_error", "wall_s", "wall_per_frame_s", "ppp_measured")


def _v(x):
    """A finite number, a string or None (pandas' NaN and numpy scalars cleaned)."""
    if x is None or isinstance(x, str | bool):
        return x
    try:
        f = float(x)
    except (TypeError, ValueError):
        return None
    if not math.isfinite(f):
        return None
    return int(f) if isinstance(x, int) else f


def _row(method, ppp, ppp_measured, values: dict, *, status, error, reasons, seed=None, frames=None) -> dict:
    out = {"method": method, "ppp": ppp, "ppp_measured": ppp_measured, "seed": seed, "frames": frames}
    for k in ("yield", "ghost_fraction", "position_error_px", "velocity_error", "velocity_error_mm_s",
              "track_velocity_error", "acceleration_error", "binned_coverage", "wall_s"):
        out[k] = _v(values.get(k))
    n_per = values.get("frames_used", frames)
    out["wall_per_frame_s"] = out["wall_s"] / n_per if out["wall_s"] is not None and n_per else None
    out.update(status=status, error=error or "")
    nulls = {k: (reasons.get(k) or error or "not computed") for k in out
             if out[k] is None and k not in ("error", "seed", "frames")}
    if nulls:
        out["null_reasons"] = nulls
    return out


def study_rows(table) -> list[dict]:
    """The rows of ``results.json`` from a sweep table (a pandas DataFrame or a list of row
    dicts, as ``mitpiv sweep`` records them): per point, one row per method that ran."""
    records = table.to_dict("records") if hasattr(table, "to_dict") else list(table)
    rows = []
    for r in records:
        get = lambda k, r=r: _v(r.get(k))  # noqa: E731
        ppp = get("param.seeding.ppp")
        ppp = ppp if ppp is not None else get("ppp")
        seed = get("param.seed")
        frames = get("frames")
        frames = frames if frames is not None else get("param.sequence.frames")
        one = {"seed": None if seed is None else int(seed), "frames": None if frames is None else int(frames)}
        if r.get("status") != "ok":
            err = f"the sweep point failed: {r.get('error')}"
            for m in ("mitpiv-stb",) + tuple(x for x, c in (("openlpt-stb", "param.compare.openlpt"),
                                                            ("mitpiv-tomo", "param.compare.tomo")) if r.get(c)):
                rows.append(_row(m, ppp, None, {}, status="failed", error=err, reasons={}, **one))
            continue
        measured = get("ppp")
        secs = [get("seconds.otf"), get("seconds.track")]
        rows.append(_row("mitpiv-stb", ppp, measured, {
            "yield": get("yield"), "ghost_fraction": get("ghost_fraction"), "position_error_px": get("position_error_px"),
            "velocity_error": get("binned_error_rel"), "velocity_error_mm_s": get("binned_mean_error_mm_s"),
            "track_velocity_error": get("velocity_error_rel"), "acceleration_error": get("acceleration_error_rel"),
            "binned_coverage": get("binned_coverage"),
            "wall_s": sum(secs) if None not in secs else None}, status="ok", error="", reasons={}, **one))
        if r.get("openlpt.status") is not None and not (isinstance(r.get("openlpt.status"), float)):
            ok = r["openlpt.status"] == "ok"
            rows.append(_row("openlpt-stb", ppp, measured, {
                "yield": get("openlpt.yield"), "ghost_fraction": get("openlpt.ghost_fraction"),
                "position_error_px": get("openlpt.position_error_px"), "velocity_error": get("openlpt.binned_error_rel"),
                "velocity_error_mm_s": get("openlpt.binned_mean_error_mm_s"),
                "track_velocity_error": get("openlpt.velocity_error_rel"),
                "acceleration_error": get("openlpt.acceleration_error_rel"),
                "binned_coverage": get("openlpt.binned_coverage"), "wall_s": get("openlpt.wall_s")},
                status="ok" if ok else "failed", error="" if ok else str(r.get("openlpt.error")), reasons={}, **one))
        if r.get("tomo.status") is not None and not (isinstance(r.get("tomo.status"), float)):
            from mitpiv.studies.kinds.tracking.compare import TOMO_NOT_APPLICABLE

            ok = r["tomo.status"] == "ok"
            na = {k: TOMO_NOT_APPLICABLE for k in ("yield", "ghost_fraction", "position_error_px")}
            na["track_velocity_error"] = na["acceleration_error"] = "tomographic PIV has no particle tracks"
            pairs = get("tomo.pairs")
            rows.append(_row("mitpiv-tomo", ppp, measured, {
                "velocity_error": get("tomo.binned_error_rel"), "velocity_error_mm_s": get("tomo.binned_mean_error_mm_s"),
                "binned_coverage": get("tomo.binned_coverage"), "wall_s": get("tomo.wall_s"),
                "frames_used": None if pairs is None else pairs + 1},
                status="ok" if ok else "failed", error="" if ok else str(r.get("tomo.error")), reasons=na, **one))
    return sorted(rows, key=lambda x: (x["method"], -1.0 if x["ppp"] is None else x["ppp"],
                                       -1 if x["seed"] is None else x["seed"]))


def study_summary(rows) -> list[dict]:
    """Per method and density: the mean of :data:`SUMMARY_KEYS` over the seeds' ``ok`` rows
    and its Student-t 95 % interval (``<key>_ci``: ``[low, high]``, ``null`` with fewer than
    two values), ``n`` the rows averaged, ``seeds`` their seeds and ``failed`` the seeds
    whose row failed (a failure is a result, not a missing value: it is counted, not averaged)."""
    from scipy import stats

    groups: dict = {}
    for r in rows:
        groups.setdefault((r["method"], r["ppp"]), []).append(r)
    out = []
    for (method, ppp), rs in sorted(groups.items(), key=lambda kv: (kv[0][0], -1.0 if kv[0][1] is None else kv[0][1])):
        ok = [r for r in rs if r.get("status") == "ok"]
        entry = {"method": method, "ppp": ppp, "n": len(ok), "seeds": [r.get("seed") for r in ok],
                 "failed": [r.get("seed") for r in rs if r.get("status") != "ok"]}
        for k in SUMMARY_KEYS:
            vals = [r[k] for r in ok if r.get(k) is not None]
            entry[k] = sum(vals) / len(vals) if vals else None
            if len(vals) >= 2:
                m = entry[k]
                sd = math.sqrt(sum((v - m) ** 2 for v in vals) / (len(vals) - 1))
                half = float(stats.t.ppf(0.975, len(vals) - 1)) * sd / math.sqrt(len(vals))
                entry[f"{k}_ci"] = [m - half, m + half]
            else:
                entry[f"{k}_ci"] = None
        out.append(entry)
    return out


def _read_table(sweep_dir: Path):
    import pandas as pd

    for name, reader in (("results.parquet", pd.read_parquet), ("results.csv", pd.read_csv)):
        if (sweep_dir / name).is_file():
            return reader(sweep_dir / name)
    raise FileFormatError(f"tracking study: {str(sweep_dir)!r} holds no sweep table (results.parquet / results.csv); "
                          f"run 'mitpiv sweep scenes/tracking_lpt/study.toml --out {sweep_dir}' first.")


def _plot(rows, summary, metric, label, log, path):
    """One figure per metric against ppp: per method the mean over the seeds with its 95 %
    interval as error bars, and every seed's value as a small dot."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from mitpiv.io.figures import save_figure

    fig, ax = plt.subplots(figsize=(7.0, 3.6))
    drawn = 0
    for method, marker in zip(("mitpiv-stb", "openlpt-stb", "mitpiv-tomo"), "osd", strict=True):
        pts = sorted((e["ppp"], e[metric], e[f"{metric}_ci"]) for e in summary if e["method"] == method
                     and e["ppp"] is not None and e.get(metric) is not None)
        if not pts:
            continue
        x = [p[0] for p in pts]
        y = [p[1] for p in pts]
        err = [[0.0 if p[2] is None else max(p[1] - p[2][0], 0.0) for p in pts],
               [0.0 if p[2] is None else max(p[2][1] - p[1], 0.0) for p in pts]]
        line = ax.errorbar(x, y, yerr=err, marker=marker, capsize=3, label=method)
        seeds = [(r["ppp"], r[metric]) for r in rows if r["method"] == method and r["ppp"] is not None
                 and r.get(metric) is not None and r.get("seed") is not None]
        if seeds:
            ax.plot(*zip(*seeds, strict=True), ls="none", marker=".", ms=3, alpha=0.5, color=line[0].get_color())
        drawn += 1
    ax.set_xscale("log")
    if log and drawn:
        ax.set_yscale("log")
    ax.set_xlabel("particles per pixel (ppp)")
    ax.set_ylabel(label)
    if metric == "yield":
        ax.set_ylim(0, 1.02)
    elif metric == "ghost_fraction":
        ax.set_ylim(bottom=0)
    if metric in ("yield", "ghost_fraction"):
        for ppp, name, style in PUBLISHED_LIMITS:
            ax.axvline(ppp, color="0.4", ls=style, lw=1.0, label=name)
    ax.grid(True, which="both", alpha=0.3)
    if drawn:  # beside the axes: inside, it hid points near 0 (OpenLPT's yield)
        ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0)
    else:
        ax.text(0.5, 0.5, "no values", transform=ax.transAxes, ha="center")
    fig.tight_layout()
    save_figure(fig, path, dpi=100)


def write_tracking_study(sweep_dir, out_dir) -> dict:
    """Write ``results.json`` and ``<metric>.png`` per metric of :data:`METRICS` from a sweep
    folder (``mitpiv sweep`` of a tracking experiment, with or without ``[compare]``).

    Returns the JSON written: ``sweep`` (the folder), ``written_by`` (the mitpiv commit that
    wrote the files; the sweep's points record their own stage keys), ``definitions`` (the
    columns' meaning), ``rows`` (:func:`study_rows`), ``summary`` (:func:`study_summary`) and
    ``figures`` (file names).
    """
    from mitpiv.io import write_json
    from mitpiv.replications.frame import _commit

    sweep = Path(sweep_dir)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rows = study_rows(_read_table(sweep))
    summary = study_summary(rows)
    figures = []
    for metric, label, log in METRICS:
        _plot(rows, summary, metric, label, log, out / f"{metric}.png")
        figures.append(f"{metric}.png")
    doc = {"sweep": str(sweep), "written_by": _commit(), "definitions": __doc__.split("Rows")[1].strip(),
           "rows": rows, "summary": summary, "figures": figures}
    write_json(out / "results.json", doc)
    _write_report(rows, summary, figures, out / "report.md")
    return doc


def _fmt(x, spec):
    return "n/a" if x is None else format(x, spec)


def _ci(e, key, spec):
    """``mean [low, high]`` of a summary entry (``n/a`` without a value; the mean alone
    without an interval)."""
    m, ci = e.get(key), e.get(f"{key}_ci")
    if m is None:
        return "n/a"
    return format(m, spec) + ("" if ci is None else f" [{format(ci[0], spec)}, {format(ci[1], spec)}]")


def _write_report(rows, summary, figures, path) -> None:
    """``report.md``: the summary over seeds (mean and 95 % interval per method and
    density), then one table line per method, density and seed (the rows of results.json),
    and the figures."""
    from mitpiv.io import write_text

    lines = ["# Tracking against particle image density", "",
             "Yield, ghosts and position error by the LPT Challenge's definitions; velocity error on the shared "
             "Eulerian grid, relative to the RMS bin speed; acceleration error per particle, relative to the RMS "
             "acceleration; wall time of the method's own work per frame. Definitions in `results.json`.", "",
             "## Over the seeds: mean [Student-t 95 % interval]", "",
             "| ppp | method | n | failed | yield | ghost fraction | position error [px] | velocity error | "
             "acceleration error | wall per frame [s] |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for e in sorted(summary, key=lambda e: (e.get("ppp") or 0.0, e["method"])):
        lines.append(f"| {_fmt(e.get('ppp'), 'g')} | {e['method']} | {e['n']} | {len(e['failed'])} | "
                     f"{_ci(e, 'yield', '.3f')} | {_ci(e, 'ghost_fraction', '.4f')} | "
                     f"{_ci(e, 'position_error_px', '.3f')} | {_ci(e, 'velocity_error', '.4f')} | "
                     f"{_ci(e, 'acceleration_error', '.3f')} | {_ci(e, 'wall_per_frame_s', '.2f')} |")
    lines += ["", "## Every run", "",
              "| ppp | method | seed | status | yield | ghost fraction | position error [px] | velocity error | "
              "acceleration error | wall [s] |",
              "|---|---|---|---|---|---|---|---|---|---|"]
    for r in sorted(rows, key=lambda r: (r.get("ppp") or 0.0, r["method"], r.get("seed") or 0)):
        st = r.get("status", "ok")
        status = st if st == "ok" else f"{st}: {r.get('error', '')}"
        lines.append(f"| {_fmt(r.get('ppp'), 'g')} | {r['method']} | {_fmt(r.get('seed'), 'd')} | "
                     f"{status.replace('|', '/')} | "
                     f"{_fmt(r.get('yield'), '.3f')} | {_fmt(r.get('ghost_fraction'), '.4f')} | "
                     f"{_fmt(r.get('position_error_px'), '.3f')} | {_fmt(r.get('velocity_error'), '.4f')} | "
                     f"{_fmt(r.get('acceleration_error'), '.3f')} | {_fmt(r.get('wall_s'), '.0f')} |")
    lines += ["", *[f"![{f}]({f})" for f in figures], ""]
    write_text(path, "\n".join(lines))
