"""A parameter sweep: MART iterations against reconstruction quality Q, repeated over
random seeds (each seed a new particle field), run in parallel on a local Dask cluster.
The plot shows the mean over the seeds with error bars of one standard deviation.

    .venv/bin/python examples/sweep.py            # iterations 1, 3, 10 x 3 seeds, 128 px (~1 min on 2 cores)
    .venv/bin/python examples/sweep.py --small    # iterations 1, 3 x 2 seeds, 80 px, in this process

From the command line: ``.venv/bin/mitpiv sweep study.toml --out out/study``. A rerun skips the
points already done; a failed point is recorded in the table with its error.
Writes results.csv / results.parquet (one row per point), sweep.png and a run folder
per point (points/<id>/, each with its own report).
"""

import argparse
from pathlib import Path

from mitpiv.studies import run_sweep


def main():
    cli = argparse.ArgumentParser(description="a sweep over MART iterations and seeds")
    cli.add_argument("--small", action="store_true", help="4 small points (the test suite's quick run)")
    cli.add_argument("--out", default="out/examples/sweep", help="output folder")
    cli.add_argument("--workers", type=int, default=2, help="Dask worker processes")
    args = cli.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    scene = Path(__file__).resolve().parents[1] / "scenes" / "tomo4" / "scene.xml"
    resolution, iterations, seeds = (80, [1, 3], [1, 2]) if args.small else (128, [1, 3, 10], [1, 2, 3])

    # The base experiment (see examples/tomo_experiment.py for every table).
    (out / "experiment.toml").write_text(f"""
    name = "iterations"
    [scene]
    xml = "{scene.as_posix()}"
    params = {{ resolution = {resolution}, thickness_mm = 4 }}
    [seeding]
    box_min_mm = [-5.0, -5.0, -2.0]
    box_max_mm = [5.0, 5.0, 2.0]
    ppp = 0.04                    # particles per pixel of the first camera
    [flow]
    kind = "uniform"
    velocity_mm_s = [100.0, 0.0, 0.0]
    dt_s = 0.002
    [reconstruction]
    method = "mart"
    bounds_mm = [-4.0, 4.0, -4.0, 4.0, -1.6, 1.6]
    voxel_mm = {0.125 if args.small else 0.1}
    [piv]
    windows = [16]
    """)

    # The study: every combination of the [grid] lists is a point (dotted keys of the
    # experiment); "seed" repeats each setting on a new particle field.
    (out / "study.toml").write_text(f"""
    experiment = "experiment.toml"
    [grid]
    "reconstruction.iterations" = {iterations}
    seed = {seeds}
    [plot]
    x = "reconstruction.iterations"
    y = "frame0.Q"
    """)

    # --small: one worker thread in this process (no worker start-up); else worker processes
    table = run_sweep(out / "study.toml", out, workers=1 if args.small else args.workers, processes=not args.small)
    print(table[["param.reconstruction.iterations", "param.seed", "frame0.Q", "status"]].to_string(index=False))
    print(table.groupby("param.reconstruction.iterations")["frame0.Q"].agg(["mean", "std"]))
    print(f"-> {out / 'sweep.png'}, {out / 'results.csv'}")


if __name__ == "__main__":  # Dask starts worker processes that import this file: run only as a script
    main()
