"""Command-line interface: ``mitpiv render``, ``info``, ``sensor``, ``decode``, ``refocus``,
``reconstruct``, ``evaluate``, ``piv``, ``run``, ``schema``, ``sweep`` and ``bench``.

Thin: parses arguments, calls library functions, shows progress (``--quiet`` silences it),
prints where results went. Errors from mitpiv print as one line and exit with status 2.
Experiment settings come from the experiment schema (:mod:`mitpiv.studies.schema`): every
field is settable as ``--set table.field=value``, the common ones by typed flags.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys

from mitpiv.errors import MitpivError
from mitpiv.reconstruct.images import RECONSTRUCT_METHODS

#: Typed flags of ``mitpiv run`` and the experiment field each sets (unit in the name).
RUN_FLAGS = {"seed": "seed", "method": "reconstruction.method", "iterations": "reconstruction.iterations",
             "voxel-mm": "reconstruction.voxel_mm", "dt-s": "flow.dt_s", "spp": "render.spp",
             "ppp": "seeding.ppp", "count": "seeding.count"}


def _parse_define(items: list[str]) -> dict:
    out = {}
    for item in items or []:
        if "=" not in item:
            raise MitpivError(f"-D expects name=value, got {item!r}.")
        k, v = item.split("=", 1)
        out[k.strip()] = v.strip()
    return out


def cmd_render(args) -> int:
    import mitpiv

    files = mitpiv.render_scene(
        args.scene, out_dir=args.out, frames=args.frames, params=_parse_define(args.define), spp=args.spp, seed=args.seed,
        progress=_progress(args),
    )
    print(f"wrote {len(files)} EXR file(s) to {args.out}")
    return 0


def cmd_info(args) -> int:
    from mitpiv.io import read_exr

    img, meta = read_exr(args.file)
    print(f"{args.file}: {img.shape[1]}x{img.shape[0]} float32, min {img.min():.6g}, max {img.max():.6g}, sum {img.sum(dtype='float64'):.6g}")
    print(json.dumps(meta, indent=2, sort_keys=True))
    return 0


def cmd_sensor(args) -> int:
    from pathlib import Path

    from mitpiv.imaging import SensorModel, apply_sensor_set
    from mitpiv.io import read_exr
    from mitpiv.io.counts import write_counts

    model = SensorModel(
        exposure=args.exposure, peak_photons=args.peak_photons, quantum_efficiency=args.qe, shot_noise=args.shot_noise,
        dark_current_e_per_s=args.dark_current, exposure_time_s=args.exposure_time, full_well_e=args.full_well,
        read_noise_e=args.read_noise, gain_e_per_count=args.gain, black_level=args.black_level,
        gaussian_noise_percent=args.noise_percent, bit_depth=args.bit_depth,
    )
    inputs = [(Path(f), *read_exr(f)) for f in args.files]  # read everything before writing anything
    # one exposure for the whole set (scene-wide), one noise stream per (camera, frame)
    images, where = {}, {}
    keys = [(str(meta.get("sensor_id") or path.stem), int(meta.get("frame") or 0)) for path, _, meta in inputs]
    for key, (path, img, _) in zip(keys, inputs, strict=True):
        if key in images:
            raise MitpivError(f"sensor: {path} and {where[key]} are both camera {key[0]!r}, frame {key[1]}; give each "
                              f"(camera, frame) once.")
        images[key], where[key] = img if img.ndim == 2 else img[..., 0], path
    # all-black output (e.g. no --exposure: radiance taken as photons rounds to 0) is refused
    res = apply_sensor_set(images, model, seed=args.seed, progress=_progress(args), on_degenerate="raise")
    out = Path(args.out)
    for key, (path, _, meta) in zip(keys, inputs, strict=True):
        target = out / f"{path.stem}.{args.format}"
        write_counts(target, res.counts[key], {**meta, "sensor_model": res.metadata(key)})
    print(f"{len(inputs)} image(s), exposure {res.exposure:.4g} photons per unit radiance -> {out}")
    return 0


def cmd_decode(args) -> int:
    from pathlib import Path

    from mitpiv.lightfield import calibrate_mla, decode
    from mitpiv.render.render import write_preview

    cal = None
    if args.calibrate:
        if args.white is None:
            raise MitpivError("decode: --calibrate needs --white (the white image to calibrate from).")
        from mitpiv.io import read_exr

        img, meta = read_exr(args.white)
        layout = args.layout or (meta.get("camera") or {}).get("mla_layout")
        if layout is None:
            raise MitpivError("decode: --calibrate needs --layout rect|hex (the white image has no camera metadata).")
        cal = calibrate_mla(img, layout=layout)
        print(f"MLA calibration: pitch {cal.pitch_px:.4f} px, rotation {cal.rotation_deg:.4f} deg, "
              f"{len(cal.axial)} lenslets, fit residual {cal.rms_residual_px:.3f} px RMS", file=sys.stderr)
    lf = decode(args.raw, cal, white=args.white, interpolation=args.interpolation, angular_oversample=args.angular_oversample)
    out = Path(args.out)
    lf.save(out)
    # Sub-aperture mosaic preview: views tiled in (v, u) order.
    write_preview(out.with_suffix(".png"), lf.mosaic())
    s, t, u, v = lf.shape
    print(f"light field L[s, t, u, v] = {s}x{t}x{u}x{v} -> {out} (+ sub-aperture mosaic {out.with_suffix('.png')})")
    return 0


def cmd_refocus(args) -> int:
    from pathlib import Path

    import numpy as np

    from mitpiv.lightfield import LightField, decode, focal_stack
    from mitpiv.render.render import write_preview

    src = Path(args.input)
    lf = LightField.load(src) if src.suffix == ".npz" else decode(src, white=args.white)
    if args.z_range is not None:
        z = np.linspace(args.z_range[0], args.z_range[1], int(args.z_range[2]))
    elif args.z:
        z = np.asarray(args.z, float)
    else:
        raise MitpivError("refocus: give --z Z [Z ...] or --z-range START STOP COUNT (mm from the focal plane, + farther).")
    out = Path(args.out)
    stack = focal_stack(lf, z, method=args.method, magnification=args.magnification, out=out,
                        progress=_progress(args))
    k = int(np.argmin(np.abs(z)))
    write_preview(out.with_suffix(".png"), np.asarray(stack[k]))
    print(f"focal stack {stack.shape[0]} planes x {stack.shape[1]}x{stack.shape[2]} ({args.method}) -> {out}")
    return 0




def _grid_from_args(args):
    from mitpiv.grid import VoxelGrid

    b = args.bounds
    return VoxelGrid.from_bounds((b[0], b[2], b[4]), (b[1], b[3], b[5]),
                                 args.voxel_mm if len(args.voxel_mm) == 3 else args.voxel_mm[0])


def cmd_reconstruct(args) -> int:
    import time
    from pathlib import Path

    import numpy as np

    from mitpiv.io import read_exr, write_volume
    from mitpiv.reconstruct.images import reconstruct_images
    from mitpiv.render.render import write_preview

    if len(args.voxel_mm) not in (1, 3):
        raise MitpivError(f"reconstruct: --voxel-mm takes 1 (cubic) or 3 (dx dy dz) sizes in mm, got "
                          f"{len(args.voxel_mm)}.")
    out = Path(args.out)
    if out.suffix != ".npz":
        raise MitpivError(f"reconstruct: --out must be a .npz file, got {str(out)!r}.")
    grid = _grid_from_args(args)
    inputs = [read_exr(f) for f in args.images]
    images = [img if img.ndim == 2 else img[..., 0] for img, _ in inputs]
    metas = [m for _, m in inputs]
    logging.getLogger("mitpiv").info("grid %dx%dx%d voxels of %s mm, %d image(s), method %s", grid.shape[2],
                                     grid.shape[1], grid.shape[0], grid.voxel_mm, len(images), args.method)
    t0 = time.perf_counter()
    vol, info = reconstruct_images(images, metas, grid, args.method, whites=args.white, iterations=args.iterations,
                                   mu=args.mu, weights=args.weights, interpolation=args.interpolation,
                                   preprocess=args.preprocess, combine=args.combine,
                                   threshold_k=None if args.threshold_k < 0 else args.threshold_k,
                                   rays_per_pixel=args.rays_per_pixel, progress=_progress(args))
    elapsed = time.perf_counter() - t0
    metrics = {}
    if args.truth:
        from mitpiv import analysis
        from mitpiv.io import read_truth

        truth = analysis.truth_volume(read_truth(args.truth)["positions_mm"][args.frame], grid)
        metrics = analysis.volume_quality(vol, truth)
    record = {"method": args.method, "images": [str(f) for f in args.images], "grid": grid.to_dict(),
              "seconds": elapsed, "metrics": metrics,
              "info": {k: v for k, v in info.items() if isinstance(v, int | float | str | list)}}
    write_volume(out, vol, record)
    write_preview(out.with_suffix(".png"), np.asarray(vol).max(axis=0))
    print(f"volume {vol.shape} ({args.method}, {elapsed:.1f} s) -> {out} (+ max projection {out.with_suffix('.png')})")
    for k, v in metrics.items():
        print(f"  {k:4s} {v:.4f}")
    return 0


def _truth_frame(path, frame: int):
    from mitpiv.io import read_truth

    truth = read_truth(path)
    n = truth["positions_mm"].shape[0]
    if not (-n <= frame < n):
        raise MitpivError(f"--frame {frame} is out of range: {path} holds {n} frame(s).")
    return truth


def cmd_evaluate(args) -> int:
    from pathlib import Path

    from mitpiv import analysis
    from mitpiv.io.records import write_json

    out_path = Path(args.out) if args.out else None
    if out_path is not None and out_path.suffix != ".json":
        raise MitpivError(f"evaluate: --out must be a .json file, got {str(out_path)!r}.")
    from mitpiv.io import read_volume

    vol, grid, _ = read_volume(args.volume)
    truth = _truth_frame(args.truth, args.frame)
    metrics, res = analysis.evaluate_volume(vol, grid, truth["positions_mm"][args.frame], method=args.method,
                                            threshold_rel=args.threshold_rel, radius_voxels=args.radius_voxels)
    out = {"volume": str(args.volume), "truth": str(args.truth), "frame": args.frame, "method": args.method, **metrics}
    s = out["particles"]
    q_rank = out["Q'"]
    print(f"Q {out['Q']:.4f}  Q* {out['Q*']:.4f}  Q' {q_rank:.4f}  SNR {out['SNR']:.2f}")
    print(f"particles: {s['n_found']} found, {s['n_truth']} in the volume, {s['n_matched']} matched "
          f"(detection {100 * s['detection_rate']:.1f} %, ghosts {100 * s['ghost_fraction']:.1f} %)")
    for name in ("bias", "rms", "u95"):
        v = s[f"{name}_vox"]
        print(f"  {name:4s} [voxels] x {v[0]:+.3f}  y {v[1]:+.3f}  z {v[2]:+.3f}")
    if out_path is not None:
        write_json(out_path, out)
        res.plot(out_path.with_suffix(".png"))
        print(f"-> {out_path} (+ error PDFs {out_path.with_suffix('.png')})")
    return 0


def cmd_piv(args) -> int:
    from pathlib import Path

    from mitpiv import analysis

    out = Path(args.out)
    if out.suffix != ".npz":
        raise MitpivError(f"piv: --out must be a .npz file, got {str(out)!r}.")
    from mitpiv.io import read_volume

    va, grid, _ = read_volume(args.vol_a)
    vb, grid_b, _ = read_volume(args.vol_b)
    if grid_b != grid:
        raise MitpivError(f"piv: the volumes lie on different grids ({grid.to_dict()} vs {grid_b.to_dict()}); "
                          f"reconstruct both frames on the same --bounds and --voxel.")
    windows = [tuple(int(x) for x in w.split("x")) if "x" in w else int(w) for w in args.windows]
    if any(isinstance(w, tuple) and len(w) != 3 for w in windows):
        raise MitpivError(f"piv: --windows entries are N or WXxWYxWZ, got {args.windows}.")
    dt, flow, t0 = args.dt_s, None, 0.0
    if args.truth:
        from mitpiv.physics.flows import flow_from_dict

        truth = _truth_frame(args.truth, args.frame)
        if not truth["flow"]:
            raise MitpivError(f"piv: {args.truth} names no analytic flow; velocity errors need one.")
        if truth["times_s"].size < args.frame + 2:
            raise MitpivError(f"piv: {args.truth} has no frame after --frame {args.frame}.")
        flow = flow_from_dict(truth["flow"])
        t0 = float(truth["times_s"][args.frame])
        dt = dt if dt else float(truth["times_s"][args.frame + 1] - t0)
    field = analysis.piv3d(va, vb, grid, windows=windows, overlap=args.overlap, deform=not args.no_deform,
                           interpolation=args.interpolation, normalised=args.normalised, threshold=args.threshold,
                           replace=None if args.replace == "none" else args.replace, dt_s=dt,
                           progress=_progress(args))
    metrics = {}
    if flow is not None:
        res = analysis.velocity_error(field, flow, t0_s=t0)
        metrics = analysis.velocity_error_summary(res)
        field.info["velocity_error"] = metrics
        analysis.plot_velocity_error(field, res, out.with_suffix(".error.png"))
    field.save(out)
    print(f"{field.n_vectors} vectors {field.shape[::-1]} (x, y, z), {field.info['seconds']:.1f} s, "
          f"outliers {100 * field.outlier_ratio:.2f} %, invalid {field.info['invalid']} -> {out}")
    if metrics:
        r, b = metrics["rms_vox"], metrics["bias_vox"]
        print(f"  velocity error [voxels]: rms x {r[0]:.4f} y {r[1]:.4f} z {r[2]:.4f}; "
              f"bias x {b[0]:+.4f} y {b[1]:+.4f} z {b[2]:+.4f} (plot {out.with_suffix('.error.png')})")
    return 0


def _run_overrides(args) -> dict:
    from mitpiv.studies.schema import parse_value

    ov = {}
    for item in args.set or []:
        if "=" not in item:
            raise MitpivError(f"--set expects table.field=value (e.g. reconstruction.iterations=10), got {item!r}.")
        k, v = item.split("=", 1)
        ov[k.strip()] = parse_value(v.strip())
    for flag, key in RUN_FLAGS.items():
        v = getattr(args, flag.replace("-", "_"), None)
        if v is not None:
            ov[key] = v
    return ov


def cmd_run(args) -> int:
    from mitpiv.studies import check_experiment, run_experiment

    overrides = _run_overrides(args)
    if args.check:
        cfg = check_experiment(args.experiment, overrides)
        print(f"{args.experiment}: a valid {cfg.kind} experiment ({cfg.name}, seed {cfg.seed}); nothing was run.")
        return 0
    if args.out is None:
        raise MitpivError("run: give --out DIR (the run folder), or --check to validate only.")
    result = run_experiment(args.experiment, args.out, overrides=overrides, progress=_progress(args))
    print(f"{result.headline()} -> {args.out}/report/report.md")
    return 0


def cmd_schema(args) -> int:
    from mitpiv.studies.kinds import get_kind
    from mitpiv.studies.schema import describe

    kind = get_kind(args.kind, source="schema")
    print(describe(kind.schema, title=f"Experiment kind {kind.name!r}: {kind.describe}"))
    return 0


def cmd_sweep(args) -> int:
    from mitpiv.studies import run_sweep

    df = run_sweep(args.study, args.out, scheduler=args.scheduler, workers=args.workers, full=args.full,
                   progress=_progress(args))
    ok = int((df["status"] == "ok").sum())
    print(f"{ok}/{len(df)} points ok -> {args.out}/results.csv, results.parquet")
    for _, row in df[df["status"] != "ok"].iterrows():
        print(f"  failed {row['point']}: {row['error']}")
    return 0


def cmd_bench(args) -> int:
    from mitpiv.studies.accuracy import accuracy_time

    stages = [s.strip() for s in args.stages.split(",")] if args.stages else None
    accuracy_time(args.out, size="quick" if args.quick else "full", stages=stages, seed=args.seed)
    print(f"wrote {args.out}/accuracy_time.md, accuracy_time.csv and pareto_*.png")
    return 0


def cmd_replicate(args) -> int:
    from mitpiv.studies.replication import get_study, list_studies, replicate

    if args.list or args.study is None:
        names = list_studies()
        if not names:
            print("no replications are registered yet")
        for n in names:
            st = get_study(n)
            print(f"{n:20s} {st.title} (paper {st.paper})")
        if args.study is None and not args.list:
            raise MitpivError("replicate: name a study (see the list above), e.g. mitpiv replicate NAME --quick.")
        return 0
    res = replicate(args.study, args.out, quick=args.quick, seed=args.seed, workers=args.workers,
                    progress=_progress(args))
    rows = res["rows"]
    n_ok = sum(1 for r in rows if r["agrees"] is True)
    n_cmp = sum(1 for r in rows if r["agrees"] is not None)
    out = args.out or f"out/replicate/{args.study}{'-quick' if args.quick else ''}"
    print(f"{args.study} ({res['scale']}): {n_ok}/{n_cmp} rows agree with the paper, {res['wall_s']:.0f} s "
          f"-> {out}/report.md, results.json")
    return 0


def _progress(args) -> bool:
    return not getattr(args, "quiet", False)


def _schema_field(key: str):
    """The FieldInfo of a dotted experiment key in the tomo schema (a union's first member)."""
    from mitpiv.studies.kinds.tomo import schema
    from mitpiv.studies.schema import models_in

    node = schema()
    *tables, name = key.split(".")
    for t in tables:
        node = models_in(node.model_fields[t].annotation)[0]
    return node.model_fields[name]


def _flag_kwargs(key: str) -> dict:
    """argparse type, choices and help of a typed ``mitpiv run`` flag, from the schema."""
    import typing

    fi = _schema_field(key)
    ann = fi.annotation
    while typing.get_origin(ann) is not None and typing.get_origin(ann) is not typing.Literal:
        ann = typing.get_args(ann)[0]  # Annotated[...] / X | None / a union: its first member
    kw = {"help": f"{fi.description} (sets {key})", "default": None}
    if typing.get_origin(ann) is typing.Literal:
        kw.update(type=str, choices=list(typing.get_args(ann)))
    else:
        kw["type"] = int if ann is int else float
    return kw


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="mitpiv", description="Physically based rendering testbed for volumetric PIV.")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress bars or progress messages")
    p.add_argument("--verbose", "-v", action="store_true", help="debug messages (every step of long loops)")
    sub = p.add_subparsers(dest="command", required=True)
    r = sub.add_parser("render", help="render every sensor of a scene XML for each frame to EXR + PNG")
    r.add_argument("scene", help="scene XML file")
    r.add_argument("--out", required=True, help="output folder")
    r.add_argument("--frames", type=int, nargs="+", default=[0, 1], help="frames to render (default: 0 1)")
    r.add_argument("-D", dest="define", action="append", metavar="NAME=VALUE", help="scene parameter ($NAME)")
    r.add_argument("--spp", type=int, default=None, help="samples per pixel (camera-tracing integrators)")
    r.add_argument("--seed", type=int, default=0)
    r.set_defaults(func=cmd_render)
    i = sub.add_parser("info", help="print an EXR file's mitpiv metadata")
    i.add_argument("file")
    i.set_defaults(func=cmd_info)
    s = sub.add_parser("sensor", help="apply the camera sensor model to rendered EXRs, write integer images")
    s.add_argument("files", nargs="+", help="rendered EXR files")
    s.add_argument("--out", required=True, help="output folder")
    s.add_argument("--format", choices=["png", "tif", "exr"], default="png", help="png/tif: 8/16-bit for PIV software; exr: uint + metadata")
    s.add_argument("--bit-depth", type=int, default=12, help="8, 10, 12, 14 or 16 (default 12)")
    s.add_argument("--exposure", type=float, default=None, help="photons per pixel per unit of image value")
    s.add_argument("--peak-photons", type=float, default=None, help="alternative: photons in the brightest pixel")
    s.add_argument("--qe", type=float, default=1.0, help="quantum efficiency (0, 1]")
    s.add_argument("--shot-noise", action="store_true", help="Poisson photon noise")
    s.add_argument("--dark-current", type=float, default=0.0, help="dark electrons per second")
    s.add_argument("--exposure-time", type=float, default=0.0, help="exposure time [s] (for dark current)")
    s.add_argument("--full-well", type=float, default=None, help="full-well capacity [e-]")
    s.add_argument("--read-noise", type=float, default=0.0, help="read noise [e- RMS]")
    s.add_argument("--gain", type=float, default=1.0, help="electrons per count")
    s.add_argument("--black-level", type=float, default=0.0, help="offset [counts]")
    s.add_argument("--noise-percent", type=float, default=0.0, help="white Gaussian noise, %% of the peak")
    s.add_argument("--seed", type=int, default=0)
    s.set_defaults(func=cmd_sensor)
    d = sub.add_parser("decode", help="decode a raw plenoptic EXR into a 4D light field (.npz) + sub-aperture mosaic")
    d.add_argument("raw", help="raw EXR rendered by a plenoptic sensor")
    d.add_argument("--out", required=True, help="output .npz")
    d.add_argument("--white", default=None, help="white EXR: devignetting and view weights")
    d.add_argument("--calibrate", action="store_true", help="calibrate the MLA from --white instead of using the metadata")
    d.add_argument("--layout", choices=["rect", "hex"], default=None, help="MLA layout for --calibrate")
    d.add_argument("--interpolation", choices=["nearest", "linear", "cubic"], default="linear")
    d.add_argument("--angular-oversample", type=int, default=1)
    d.set_defaults(func=cmd_decode)
    f = sub.add_parser("refocus", help="focal stack of a light field (.npz) or raw EXR, streamed to a .npy file")
    f.add_argument("input", help="light field .npz (mitpiv decode) or raw EXR")
    f.add_argument("--out", required=True, help="output .npy (n_z, n_t, n_s)")
    f.add_argument("--z", type=float, nargs="+", help="depths [mm] from the focal plane (+ = farther)")
    f.add_argument("--z-range", type=float, nargs=3, metavar=("START", "STOP", "COUNT"))
    f.add_argument("--method", choices=["additive", "multiplicative"], default="additive")
    f.add_argument("--magnification", choices=["natural", "constant"], default="natural")
    f.add_argument("--white", default=None, help="white EXR (raw-EXR input only)")
    f.set_defaults(func=cmd_refocus)
    c = sub.add_parser("reconstruct", help="reconstruct a volume from camera EXRs (tomographic, SAPIV or plenoptic)")
    c.add_argument("images", nargs="+", help="EXR images with camera metadata (one per camera)")
    c.add_argument("--out", required=True, help="output .npz (volume (n_z, n_y, n_x) + JSON meta)")
    c.add_argument("--method", choices=RECONSTRUCT_METHODS, default="mart")
    c.add_argument("--bounds", type=float, nargs=6, required=True, metavar=("XMIN", "XMAX", "YMIN", "YMAX", "ZMIN", "ZMAX"),
                   help="volume [mm]")
    c.add_argument("--voxel-mm", "--voxel", dest="voxel_mm", type=float, nargs="+", required=True,
                   help="voxel size [mm]: one (cubic) or three (dx dy dz) (--voxel: deprecated)")
    c.add_argument("--iterations", type=int, default=5)
    c.add_argument("--mu", type=float, default=1.0, help="MART relaxation (0, 2)")
    c.add_argument("--weights", choices=["circle", "gaussian"], default="circle")
    c.add_argument("--interpolation", choices=["linear", "cubic"], default="linear")
    c.add_argument("--preprocess", type=float, default=None, metavar="K", help="histogram threshold: background + K sigma")
    c.add_argument("--combine", choices=["additive", "multiplicative"], default="multiplicative",
                   help="sapiv / plenoptic combination")
    c.add_argument("--threshold-k", type=float, default=3.0, help="sapiv: keep mean + k sigma per plane (< 0: none)")
    c.add_argument("--white", nargs="+", default=None, help="plenoptic: white EXR per image")
    c.add_argument("--rays-per-pixel", type=int, default=16, help="drt-mart ray bundle per pixel")
    c.add_argument("--truth", default=None, help="truth .npz: print Q, Q*, Q' and SNR")
    c.add_argument("--frame", type=int, default=0, help="truth frame of the images")
    c.set_defaults(func=cmd_reconstruct)
    e = sub.add_parser("evaluate", help="find particles in a reconstructed volume, match them to the truth, print errors")
    e.add_argument("volume", help="volume .npz from 'mitpiv reconstruct'")
    e.add_argument("--truth", required=True, help="truth .npz (particle positions per frame)")
    e.add_argument("--frame", type=int, default=0, help="truth frame of the volume")
    e.add_argument("--method", choices=["gauss3", "centroid", "lsq"], default="gauss3", help="sub-voxel localisation")
    e.add_argument("--threshold-rel", type=float, default=0.1, help="peaks above this fraction of the maximum")
    e.add_argument("--radius-voxels", type=float, default=2.0, help="matching search radius [voxels]")
    e.add_argument("--out", default=None, help="metrics .json (+ error PDF plot .png)")
    e.set_defaults(func=cmd_evaluate)
    v = sub.add_parser("piv", help="multi-pass 3D cross-correlation between two reconstructed volumes")
    v.add_argument("vol_a", help="volume .npz of the first frame")
    v.add_argument("vol_b", help="volume .npz of the second frame")
    v.add_argument("--out", required=True, help="vector field .npz")
    v.add_argument("--windows", nargs="+", default=["64", "48", "32"],
                   help="window per pass: N (cubic) or WXxWYxWZ (default 64 48 32)")
    v.add_argument("--overlap", type=float, default=0.75, help="window overlap fraction [0, 1)")
    v.add_argument("--no-deform", action="store_true", help="integer window shifting instead of window deformation")
    v.add_argument("--interpolation", choices=["linear", "cubic"], default="cubic", help="deformation resampling")
    v.add_argument("--normalised", action="store_true", help="normalised cross-correlation")
    v.add_argument("--threshold", type=float, default=2.0, help="universal outlier detection threshold")
    v.add_argument("--replace", choices=["median", "interpolation", "none"], default="median")
    v.add_argument("--dt-s", "--dt", dest="dt_s", type=float, default=None,
                   help="time between the frames [s]: velocities in mm/s (--dt: deprecated)")
    v.add_argument("--truth", default=None, help="truth .npz with the flow: velocity error against it")
    v.add_argument("--frame", type=int, default=0, help="truth frame of vol_a")
    v.set_defaults(func=cmd_piv)
    x = sub.add_parser("run", help="run (or resume) an experiment TOML: render, reconstruct, evaluate, PIV, report")
    x.add_argument("experiment", help="experiment .toml")
    x.add_argument("--out", default=None, help="run folder (stages resume when rerun)")
    x.add_argument("--check", action="store_true", help="validate the experiment (every table) and run nothing")
    x.add_argument("--set", action="append", metavar="TABLE.FIELD=VALUE",
                   help="set any experiment field (a TOML value), e.g. --set piv.windows=[48,32]; see 'mitpiv schema'")
    for flag, key in RUN_FLAGS.items():
        x.add_argument(f"--{flag}", **_flag_kwargs(key))
    x.set_defaults(func=cmd_run)
    sc = sub.add_parser("schema", help="print every experiment table and field with its unit, default and range")
    sc.add_argument("--kind", default="tomo", help="experiment kind: tomo (default) or backlit")
    sc.set_defaults(func=cmd_schema)
    w = sub.add_parser("sweep", help="run a parameter study (grid or list of experiment overrides) on Dask")
    w.add_argument("study", help="study .toml")
    w.add_argument("--out", required=True, help="sweep folder (results table, one run folder per point)")
    w.add_argument("--scheduler", default=None, help="address of a running Dask scheduler (default: a local cluster)")
    w.add_argument("--workers", type=int, default=None, help="local cluster worker processes (default 2)")
    w.add_argument("--full", action="store_true", help="the full-size study (the study's [full] overrides)")
    w.set_defaults(func=cmd_sweep)
    b = sub.add_parser("bench", help="benchmarks: 'accuracy-time' measures every accuracy knob's time and error")
    b.add_argument("which", choices=["accuracy-time"], help="the benchmark to run")
    b.add_argument("--out", default="out/accuracy-time", help="output folder (tables, CSV, Pareto plots)")
    b.add_argument("--quick", action="store_true", help="the small preset (seconds; default: the full preset, ~15 min)")
    b.add_argument("--stages", default=None,
                   help="comma-separated subset of render,lightfield,reconstruct,piv,end_to_end (default all)")
    b.add_argument("--seed", type=int, default=0, help="seed of the particle field")
    b.set_defaults(func=cmd_bench)
    rp = sub.add_parser("replicate", help="replicate a published study (the paper's set-up and measures, "
                        "results side by side)")
    rp.add_argument("study", nargs="?", default=None, help="study name (see --list)")
    rp.add_argument("--list", action="store_true", help="list the replications and their papers")
    rp.add_argument("--quick", action="store_true", help="the reduced study (minutes; same code and row ids)")
    rp.add_argument("--out", default=None, help="output folder (default out/replicate/NAME[-quick]); resumes")
    rp.add_argument("--seed", type=int, default=0, help="base seed of every random stream")
    rp.add_argument("--workers", type=int, default=1, help="local Dask worker processes for independent points")
    rp.set_defaults(func=cmd_replicate)
    args = p.parse_args(argv)
    from mitpiv.progress import set_quiet

    if args.quiet:
        set_quiet(True)
    level = logging.WARNING if args.quiet else (logging.DEBUG if args.verbose else logging.INFO)
    logging.basicConfig(level=level, format="%(message)s", stream=sys.stderr)
    logging.getLogger("mitpiv").setLevel(level)
    for noisy in ("distributed", "numba", "matplotlib", "PIL"):  # other libraries stay at warnings
        logging.getLogger(noisy).setLevel(max(level, logging.WARNING))
    from tqdm.contrib.logging import logging_redirect_tqdm

    try:
        with logging_redirect_tqdm(loggers=[logging.getLogger("mitpiv")]):  # messages print above the bars
            return args.func(args)
    except MitpivError as e:
        print(f"mitpiv: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
