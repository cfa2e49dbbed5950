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
numbers: differences come from the parameters) unless "seed" is itself swept. A point that
fails is recorded in the table with its error, and the others finish. The table
(``results.csv`` and ``results.parquet``) is rewritten atomically after every finished
point, so a killed sweep loses nothing; a rerun submits only the points without a result
(a killed worker's task is retried by Dask, and the point resumes from its finished
stages).
"""

from __future__ import annotations

import hashlib
import itertools
import json
import sys
import time
import traceback
from pathlib import Path

from mitpiv.errors import ConfigError
from mitpiv.studies.experiment import load_experiment, read_toml, run_config

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
    return {"name": st.get("name", path.stem), "experiment": exp, "points": points, "plot": st.get("plot"),
            "path": path, "workers": st.get("workers")}


def point_id(overrides: dict) -> str:
    return hashlib.sha256(json.dumps(overrides, sort_keys=True, default=str).encode()).hexdigest()[:12]


def _flatten(prefix, obj, out):
    if isinstance(obj, dict):
        for k, v in obj.items():
            _flatten(f"{prefix}.{k}" if prefix else str(k), v, out)
    elif isinstance(obj, list) and all(isinstance(x, int | float) for x in obj) and len(obj) == 3:
        for axis, v in zip("xyz", obj, strict=True):
            out[f"{prefix}_{axis}"] = v
    elif isinstance(obj, int | float | str | bool) or obj is None:
        out[prefix] = obj


def run_point(experiment_path: str, overrides: dict, out_dir: str) -> dict:
    """Run one point (in a Dask worker); never raises: failures become a row with the error."""
    row = {"point": point_id(overrides), **{f"param.{k}": v for k, v in overrides.items()}}
    t0 = time.perf_counter()
    try:
        cfg = load_experiment(experiment_path, {k: v for k, v in overrides.items() if k != "label"})
        m = run_config(cfg, out_dir)
        metrics = {}
        _flatten("", {"frame0": (m.get("evaluate") or {}).get("frame0"), "frame1": (m.get("evaluate") or {}).get("frame1"),
                      "piv": m.get("piv")}, metrics)
        timings = json.loads((Path(out_dir) / "timings.json").read_text())
        row.update({"status": "ok", "error": "", **metrics, **{f"seconds.{k}": v for k, v in timings.items()},
                    "seconds.total": sum(timings.values())})
    except Exception as e:  # noqa: BLE001 - a failed point is a result, recorded in the table
        row.update({"status": "error", "error": f"{type(e).__name__}: {e}",
                    "traceback": traceback.format_exc(limit=3)})
    row["wall_s"] = time.perf_counter() - t0
    return row


def _write_table(rows, out: Path):
    import pandas as pd

    from mitpiv.io.atomic import atomic_path

    df = pd.DataFrame(rows)
    with atomic_path(out / "results.csv") as tmp:
        df.to_csv(tmp, index=False)
    with atomic_path(out / "results.parquet") as tmp:
        df.to_parquet(tmp, index=False)
    return df


def plot_sweep(table, x: str, y: str, path, *, group: str | None = None) -> None:
    """PNG of metric ``y`` against parameter ``x`` (names as in the table, "param." optional),
    one line per value of ``group``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from mitpiv.io.atomic import atomic_path

    df = table[table["status"] == "ok"] if "status" in table else table

    def col(name):
        for c in (name, f"param.{name}"):
            if c in table.columns:
                return c
        raise ConfigError(f"plot_sweep: no column {name!r}; the table has {sorted(table.columns)}.")

    cx, cy = col(x), col(y)
    import pandas as pd

    numeric = pd.api.types.is_numeric_dtype(df[cx])
    cats = list(dict.fromkeys(df[cx]))  # a categorical x (e.g. labels) keeps the study's order
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    groups = [(None, df)] if group is None else list(df.groupby(col(group), sort=False))
    for g, sub in groups:
        lab = None if g is None else f"{group} = {g}"
        if numeric:
            sub = sub.sort_values(cx)
            ax.plot(sub[cx], sub[cy], "o-", label=lab)
        else:
            ax.plot([cats.index(v) for v in sub[cx]], sub[cy], "o", ms=7, label=lab)
    if not numeric:
        ax.set_xticks(range(len(cats)), [str(c) for c in cats], rotation=30, ha="right", fontsize=8)
        ax.grid(True, axis="y", alpha=0.3)
    ax.set_xlabel(x)
    ax.set_ylabel(y)
    if group is not None:
        ax.legend(fontsize=8)
    fig.tight_layout()
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)


def run_sweep(path, out_dir, scheduler=None, *, workers: int | None = None, full: bool = False,
              progress: bool = True):
    """Run every point of the study in ``path`` on Dask; returns the results table (pandas).

    scheduler : None: a LocalCluster of ``workers`` single-threaded processes (default: the
        study's ``workers`` or 2); else the address of a running Dask scheduler.
    full : apply the study's [full] overrides (the full-size study) to every point.
    """
    from dask.distributed import Client, LocalCluster, as_completed

    st = load_study(path, full=full)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rows = {}
    for ov in st["points"]:
        f = out / "points" / point_id(ov) / "row.json"
        if f.is_file():
            row = json.loads(f.read_text())
            if row.get("status") == "ok":
                rows[row["point"]] = row
    todo = [ov for ov in st["points"] if point_id(ov) not in rows]
    if progress:
        print(f"sweep {st['name']}: {len(st['points'])} points, {len(rows)} done earlier, {len(todo)} to run",
              file=sys.stderr, flush=True)
    cluster = None
    if todo:
        if scheduler is None:
            n = int(workers or st.get("workers") or 2)
            cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None)
            client = Client(cluster)
        else:
            client = Client(scheduler)
        try:
            futures = [client.submit(run_point, str(st["experiment"]), ov, str(out / "points" / point_id(ov)),
                                     key=f"point-{point_id(ov)}", retries=2, pure=False) for ov in todo]
            for k, fut in enumerate(as_completed(futures), 1):
                row = fut.result()
                from mitpiv.io.atomic import atomic_path

                with atomic_path(out / "points" / row["point"] / "row.json") as tmp:
                    tmp.write_text(json.dumps(row, default=str))
                rows[row["point"]] = row
                _write_table(list(rows.values()), out)
                if progress:
                    print(f"sweep {st['name']}: {k}/{len(todo)} finished ({row['point']}: {row['status']}"
                          f"{' - ' + row['error'] if row['status'] != 'ok' else ''})", file=sys.stderr, flush=True)
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
    order = [point_id(ov) for ov in st["points"]]
    df = _write_table([rows[p] for p in order if p in rows], out)
    plot = st.get("plot")
    if plot and "x" in plot and "y" in plot and (df["status"] == "ok").any():
        plot_sweep(df, plot["x"], plot["y"], out / "sweep.png", group=plot.get("group"))
    return df
