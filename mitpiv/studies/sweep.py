"""Parameter sweeps over experiments, executed with Dask (a local cluster by default, any
Dask scheduler by address), with one results table and a run folder per point.

Study file (paths relative to it)::

    name = "distortion"
    experiment = "experiment.toml"              # the base experiment
    [grid]                                       # Cartesian product of the lists
    "scene.params.distortion_percent" = [0, 1, 2]
    "reconstruction.iterations" = [1, 5]
    # or instead: [[points]] tables, each a set of dotted-key overrides
    [plot]                                       # optional: metric against a parameter
    x = "scene.params.distortion_percent"
    y = "frame0.Q"
    group = "reconstruction.iterations"
    [full]                                       # optional: overrides of every point for
    "scene.params.resolution" = 512              # the full-size study (--full)

A point may carry a ``label`` (a name for the table and plots, not an experiment key).

Each point is the base experiment with its overrides; the point's folder name is a hash
of the overrides, so a rerun finds it. All points use the base seed (common random
numbers: differences come from the parameters) unless "seed" is itself swept.

Every point's experiment is validated before any point runs: the config errors of all
points are reported together. A point that fails is recorded in the table with its error,
and the others finish; ``mitpiv sweep`` then lists the failed points and exits with
status 1. The table (``results.csv`` and ``results.parquet``) is rewritten atomically after
every finished point, so a killed sweep loses nothing.

A point's result is reused on a rerun only when it succeeded and its recorded experiment
key (:func:`mitpiv.studies.runner.experiment_key`: the fully resolved experiment, the
content of its input files, the code versions) equals the point's key now: a changed base
experiment or scene file reruns the point, in its folder, where the runner's content keys
rerun only the stages it affects. A killed worker's task is retried by Dask, and the point
resumes from its finished stages (its folder's lock died with the worker). The sweep folder
is locked while a sweep runs: a second sweep on it fails at once naming the holder.
"""

from __future__ import annotations

import itertools
import logging
import time
import traceback
from pathlib import Path

from mitpiv.errors import ConfigError, MitpivError
from mitpiv.progress import Progress, bar
from mitpiv.studies.runner import content_hash, experiment_key, load_experiment, preflight, run_config
from mitpiv.studies.schema import read_toml

log = logging.getLogger(__name__)

__all__ = ["load_study", "run_sweep", "run_point", "point_id"]


def __getattr__(name):
    if name == "plot_sweep":  # moved to the report module, where every figure is made
        from mitpiv.studies.report import plot_sweep

        return plot_sweep
    raise AttributeError(name)

_STUDY_KEYS = {"name", "experiment", "grid", "points", "plot", "workers", "full"}


def load_study(path, *, full: bool = False) -> dict:
    """Read a study file: returns name, the base experiment path and the list of points
    (with ``full``, each point also carries the study's [full] overrides, the point's own
    values winning)."""
    path = Path(path)
    st = read_toml(path, "study")
    unknown = set(st) - _STUDY_KEYS
    if unknown:
        raise ConfigError(f"study {path.name}: unknown key(s) {sorted(unknown)}; expected {sorted(_STUDY_KEYS)}.")
    w = st.get("workers")
    if w is not None and (isinstance(w, bool) or not isinstance(w, int) or not 1 <= w <= 512):
        raise ConfigError(f"study {path.name}: workers = {w!r} must be a whole number in [1, 512] (local Dask worker "
                          f"processes); leave it out for 2.")
    if "experiment" not in st:
        raise ConfigError(f"study {path.name}: name the base experiment: experiment = \"experiment.toml\".")
    exp = (path.parent / st["experiment"]).resolve()
    if ("grid" in st) == ("points" in st):
        raise ConfigError(f"study {path.name}: give either a [grid] table or [[points]] tables, not "
                          f"{'both' if 'grid' in st else 'neither'}.")
    if "grid" in st:
        grid = st["grid"]
        for k, v in grid.items():
            if not isinstance(v, list) or not v:
                raise ConfigError(f"study {path.name}: [grid] {k!r} must be a non-empty list of values, got {v!r}.")
        keys = list(grid)
        points = [dict(zip(keys, combo, strict=True)) for combo in itertools.product(*(grid[k] for k in keys))]
    else:
        points = [dict(p) for p in st["points"]]
        if not points:
            raise ConfigError(f"study {path.name}: [[points]] is empty.")
    if full:
        if not isinstance(st.get("full"), dict) or not st["full"]:
            raise ConfigError(f"study {path.name}: --full needs a [full] table of overrides for the full-size study.")
        points = [{**st["full"], **p} for p in points]
    points = _unique_points(points, path.name)
    return {"name": st.get("name", path.stem), "experiment": exp, "points": points, "plot": st.get("plot"),
            "path": path, "workers": st.get("workers")}


def _unique_points(points: list[dict], study_name: str) -> list[dict]:
    """``points`` without repeats (the same overrides: the same point id, run and tabulated
    once), with a warning naming each repeat."""
    import warnings

    from mitpiv.errors import MitpivWarning

    first: dict[str, int] = {}
    out = []
    for i, p in enumerate(points):
        pid = point_id(p)
        if pid in first:
            values = ", ".join(f"{k} = {v!r}" for k, v in p.items()) or "no overrides"
            warnings.warn(f"study {study_name}: point {i + 1} ({values}) repeats point {first[pid] + 1}; it runs and "
                          f"appears in the table once. Remove the duplicate (or give it another label).",
                          MitpivWarning, stacklevel=3)
            continue
        first[pid] = i
        out.append(p)
    return out


#: Columns every sweep table has besides the parameters (param.*) and the kind's results.
SWEEP_COLUMNS = ("point", "status", "error", "traceback", "wall_s", "experiment_key", "ltpr_vs_nc*")


def check_plot(st: dict, kind, study_name: str) -> None:
    """The study's ``[plot]`` names (x, y, group) checked before any point runs: each must be
    a parameter of the points ("param." optional), a column every sweep has, or one of the
    kind's result columns (where the kind declares them, :attr:`Kind.columns`)."""
    import difflib
    from fnmatch import fnmatchcase

    plot = st.get("plot")
    if plot is None:
        return
    if not isinstance(plot, dict) or not {"x", "y"} <= set(plot) or set(plot) - {"x", "y", "group"}:
        raise ConfigError(f"study {study_name}: [plot] must hold x and y (and optionally group), column names of the "
                          f"results table, got {plot!r}.")
    params = sorted({k for p in st["points"] for k in p})
    patterns = (*SWEEP_COLUMNS, *kind.columns)
    for role in ("x", "y", "group"):
        name = plot.get(role)
        if role == "group" and name is None:
            continue
        if not isinstance(name, str):
            raise ConfigError(f"study {study_name}: [plot] {role} = {name!r} must be a column name (a string).")
        bare = name.removeprefix("param.")
        if bare in params or (not name.startswith("param.") and (not kind.columns or any(
                fnmatchcase(name, pat) for pat in patterns))):
            continue
        close = difflib.get_close_matches(bare, params + [p for p in patterns if "*" not in p], n=1, cutoff=0.5)
        hint = f"; did you mean {close[0]!r}?" if close else "."
        raise ConfigError(f"study {study_name}: [plot] {role} = {name!r} is neither a parameter of the points "
                          f"({', '.join(params) or 'none'}) nor a result column of kind {kind.name!r} "
                          f"({', '.join(patterns)}){hint} Fix the name in [plot] (nothing was run).")


def point_id(overrides: dict) -> str:
    return content_hash(overrides, length=12)


def run_point(experiment_path: str, overrides: dict, out_dir: str) -> dict:
    """Run one point (in a Dask worker); never raises: failures become a row with the error.
    The row records the point's experiment key (``experiment_key``), which a rerun compares."""
    row = {"point": point_id(overrides), **{f"param.{k}": v for k, v in overrides.items()}}
    t0 = time.perf_counter()
    try:
        cfg = load_experiment(experiment_path, {k: v for k, v in overrides.items() if k != "label"})
        row["experiment_key"] = experiment_key(cfg)
        row.update({"status": "ok", "error": "", **run_config(cfg, out_dir).row()})
    except Exception as e:  # noqa: BLE001 - a failed point is a result, recorded in the table
        row.update({"status": "error", "error": f"{type(e).__name__}: {e}",
                    "traceback": traceback.format_exc(limit=3)})
    row["wall_s"] = time.perf_counter() - t0
    return row


def add_ltpr(df):
    """LTPR columns for a sweep that compares light-field cameras with tomographic rigs
    (Shi et al.'s light-field-to-tomographic pixel ratio, ``(p_x p_y)_LF / (p_x p_y
    N_c)_Tomo``, :func:`mitpiv.physics.plenoptic.ltpr`): for every point that renders one
    plenoptic camera, one column per tomographic rig of the sweep (points rendering only
    pinhole-type cameras, several of them), ``ltpr_vs_nc{N_c}`` (``ltpr_vs_nc{N_c}_{pixels}px``
    where rigs of the same N_c differ in pixels), its pixels over the rig's. Needs the
    ``cameras.*`` columns the tomo kind records; a table without them is returned as it is."""
    import numpy as np

    need = {"cameras.n", "cameras.type", "cameras.pixels"}
    if not need <= set(df.columns):
        return df
    ok = df["cameras.pixels"].notna() & df["cameras.n"].notna() & df["cameras.type"].notna()
    lf = ok & (df["cameras.type"] == "plenoptic") & (df["cameras.n"] == 1)
    tomo = ok & ~df["cameras.type"].fillna("").str.contains("plenoptic") & (df["cameras.n"] > 1)
    if not (lf.any() and tomo.any()):
        return df
    rigs = sorted({(int(n), int(p)) for n, p in zip(df.loc[tomo, "cameras.n"], df.loc[tomo, "cameras.pixels"],
                                                      strict=True)})
    per_n = {n: sum(1 for m, _ in rigs if m == n) for n, _ in rigs}
    df = df.copy()
    for n, p in rigs:
        col = f"ltpr_vs_nc{n}" if per_n[n] == 1 else f"ltpr_vs_nc{n}_{p}px"
        df[col] = np.where(lf, df["cameras.pixels"].astype(float) / p, np.nan)
    return df


def _write_table(rows, out: Path):
    import pandas as pd

    from mitpiv.io.atomic import atomic_path

    df = add_ltpr(pd.DataFrame(rows))
    with atomic_path(out / "results.csv") as tmp:
        df.to_csv(tmp, index=False)
    with atomic_path(out / "results.parquet") as tmp:
        df.to_parquet(tmp, index=False)
    return df


def run_sweep(path, out_dir, scheduler=None, *, workers: int | None = None, full: bool = False,
              processes: bool = True, progress: Progress = None):
    """Run every point of the study in ``path`` on Dask; returns the results table (pandas).

    Parameters
    ----------
    scheduler : None: a LocalCluster of ``workers`` single-threaded processes (default: the
        study's ``workers`` or 2); else the address of a running Dask scheduler.
    full : apply the study's [full] overrides (the full-size study) to every point.
    processes : the local cluster's workers are processes (default); False: threads of this
        process (no worker start-up, and they reuse this process's compiled kernels; small
        studies and tests).
    """
    from dask.distributed import Client, LocalCluster, as_completed

    from mitpiv.io.atomic import clean_temps, folder_lock
    from mitpiv.io.records import read_json, write_json
    from mitpiv.studies.report import plot_sweep

    st = load_study(path, full=full)
    keys = _validate_points(st, Path(path).name)
    from mitpiv.studies.kinds import get_kind

    check_plot(st, get_kind(read_toml(st["experiment"]).get("kind", "tomo")), Path(path).name)
    out = Path(out_dir)
    with folder_lock(out, what="sweep folder"):
        clean_temps(out)
        rows = {}
        for ov in st["points"]:
            pid = point_id(ov)  # (a point folder's temporary files are cleaned by its run, under its lock)
            f = out / "points" / pid / "row.json"
            if f.is_file():
                try:
                    row = read_json(f)
                except MitpivError:
                    continue
                if row.get("status") == "ok" and row.get("experiment_key") == keys[pid]:
                    rows[pid] = row
                elif row.get("status") == "ok":
                    log.info("sweep %s: point %s: its experiment or input files changed since it ran; it reruns",
                             st["name"], pid)
        todo = [ov for ov in st["points"] if point_id(ov) not in rows]
        log.info("sweep %s: %d points, %d done earlier, %d to run", st["name"], len(st["points"]), len(rows),
                 len(todo))
        cluster = None
        if todo:
            if scheduler is None:
                n = int(workers or st.get("workers") or 2)
                cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=processes,
                                       dashboard_address=None)
                client = Client(cluster)
            else:
                client = Client(scheduler)
            try:
                futures = [client.submit(run_point, str(st["experiment"]), ov, str(out / "points" / point_id(ov)),
                                         key=f"point-{point_id(ov)}", retries=2, pure=False) for ov in todo]
                points = bar(len(todo), desc=f"sweep {st['name']}", progress=progress, unit="point")
                for fut in as_completed(futures):
                    row = fut.result()
                    write_json(out / "points" / row["point"] / "row.json", row)
                    rows[row["point"]] = row
                    _write_table(list(rows.values()), out)
                    points.update()
                    log.info("sweep %s: point %s: %s%s", st["name"], row["point"], row["status"],
                             " - " + row["error"] if row["status"] != "ok" else "")
                points.close()
            finally:
                client.close()
                if cluster is not None:
                    cluster.close()
        order = [point_id(ov) for ov in st["points"]]
        df = _write_table([rows[p] for p in order if p in rows], out)
        plot = st.get("plot")
        if plot and "x" in plot and "y" in plot and (df["status"] == "ok").any():
            plot_sweep(df, plot["x"], plot["y"], out / "sweep.png", group=plot.get("group"))
    failed = df[df["status"] != "ok"]
    if len(failed):
        log.warning("sweep %s: %d of %d points failed: %s", st["name"], len(failed), len(df),
                    ", ".join(failed["point"]))
    return df


def _validate_points(st: dict, study_name: str) -> dict[str, str]:
    """Validate every point's experiment before any runs; one ConfigError lists every bad
    point. Returns each point's experiment key (by point id)."""
    from mitpiv.studies.kinds import get_kind

    keys, errors = {}, []
    for ov in st["points"]:
        try:
            cfg = load_experiment(st["experiment"], {k: v for k, v in ov.items() if k != "label"})
            preflight(cfg, get_kind(cfg.kind).stages(cfg))  # a point runs every stage
        except MitpivError as e:
            errors.append(f"point {ov}: {e}")
            continue
        keys[point_id(ov)] = experiment_key(cfg)
    if errors:
        head = f"study {study_name}: {len(errors)} of {len(st['points'])} points are invalid (nothing was run):"
        raise ConfigError(head + "\n  " + "\n  ".join(errors)) if len(errors) > 1 else \
            ConfigError(f"study {study_name}: {errors[0]}")
    return keys
