"""Command-line interface: ``mitpiv render``, ``info``, ``sensor``, ``decode``, ``refocus``,
``reconstruct``, ``evaluate``, ``piv``, ``run``, ``preview``, ``schema``, ``sweep`` and ``bench``.

Thin: parses arguments, calls library functions, shows progress (``--quiet`` silences it),
prints where results went. Errors from mitpiv print as one line and exit with status 2.
Experiment settings come from the experiment schema (:mod:`mitpiv.studies.schema`): every
field is settable as ``--set table.field=value``, the common ones by typed flags.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import os
import signal
import sys

from mitpiv.costs import MAX_ITERATIONS
from mitpiv.errors import MitpivError
from mitpiv.reconstruct.images import RECONSTRUCT_METHODS

#: Typed flags of ``mitpiv run`` and the experiment field each sets (unit in the name).
RUN_FLAGS = {"seed": "seed", "method": "reconstruction.method", "iterations": "reconstruction.iterations",
             "voxel-mm": "reconstruction.voxel_mm", "dt-s": "flow.dt_s", "spp": "render.spp",
             "ppp": "seeding.ppp", "count": "seeding.count"}


class _UsageError(Exception):
    """A command-line argument is invalid: printed as one line, exit status 2."""


class _Parser(argparse.ArgumentParser):
    """argparse with its errors raised (one line from :func:`main`, no usage dump, no exit)."""

    def error(self, message):
        verb = self.prog.removeprefix("mitpiv").strip()
        raise _UsageError(f"{verb + ': ' if verb else ''}{message} (see '{self.prog} --help').")

    def parse_args(self, args=None, namespace=None):
        argv = list(sys.argv[1:] if args is None else args)
        ns, extras = self.parse_known_args(argv, namespace)
        if extras:
            i = argv.index(extras[0]) if extras[0] in argv else 0
            prev = next((a for a in reversed(argv[:i]) if a.startswith("-")), None)
            hint = ""
            if prev in ("--voxel-mm", "--voxel"):
                hint = f" ({prev} takes one value; give three voxel sizes as DX,DY,DZ, e.g. 0.1,0.1,0.2)"
            elif prev is not None:
                hint = f" (after {prev}, which takes fewer values)"
            self.error(f"unrecognized arguments: {' '.join(extras)}{hint}")
        return ns


def _number(text: str, kind, flag_hint: str):
    try:
        v = kind(text)
    except (TypeError, ValueError):
        raise argparse.ArgumentTypeError(f"must be {flag_hint}, got {text!r}") from None
    if kind is float and not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"must be a finite number, got {text!r}")
    return v


def _int_in(lo: int, hi: int | None = None, *, hint: str = ""):
    """argparse type: a whole number in [lo, hi]."""
    rng = f"[{lo}, {hi}]" if hi is not None else f">= {lo}"

    def parse(text):
        v = _number(text, int, f"a whole number {rng}")
        if v < lo or (hi is not None and v > hi):
            raise argparse.ArgumentTypeError(f"must be a whole number {rng}, got {v}{hint}")
        return v

    parse.__name__ = "int"
    return parse


def _float_in(lo: float | None = None, hi: float | None = None, *, lo_open: bool = False, hi_open: bool = False):
    """argparse type: a finite number in the interval (open or closed ends)."""
    if lo is not None and hi is not None:
        rng = f"in {'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"
    elif lo is not None:
        rng = f"{'>' if lo_open else '>='} {lo:g}"
    else:
        rng = f"{'<' if hi_open else '<='} {hi:g}" if hi is not None else ""

    def parse(text):
        v = _number(text, float, f"a number {rng}".strip())
        bad = (lo is not None and (v < lo or (lo_open and v == lo))) or \
              (hi is not None and (v > hi or (hi_open and v == hi)))
        if bad:
            raise argparse.ArgumentTypeError(f"must be a number {rng}, got {text}")
        return v

    parse.__name__ = "float"
    return parse


def _seed(text: str) -> int:
    """argparse type of --seed: an integer in [0, 2**63) (the experiment seed range)."""
    from mitpiv.streams import SEED_MAX

    v = _number(text, int, "a whole number in [0, 2**63)")
    if not 0 <= v < SEED_MAX:
        raise argparse.ArgumentTypeError(f"must be a whole number in [0, 2**63), got {v}; give e.g. 0 or 1234")
    return v


def _window(text: str):
    """argparse type of --windows: N or WXxWYxWZ, whole numbers >= 4 [voxels]."""
    parts = text.lower().split("x")
    try:
        vals = [int(p) for p in parts]
    except ValueError:
        raise argparse.ArgumentTypeError(f"entries are N or WXxWYxWZ (whole numbers >= 4, e.g. 32 or 48x48x32), "
                                         f"got {text!r}") from None
    if len(vals) not in (1, 3) or min(vals) < 4:
        raise argparse.ArgumentTypeError(f"entries are N or WXxWYxWZ (whole numbers >= 4, e.g. 32 or 48x48x32), "
                                         f"got {text!r}")
    return vals[0] if len(vals) == 1 else tuple(vals)


def _voxel(text: str):
    """argparse type of --voxel-mm: one size, or three as DX,DY,DZ [mm], each finite and > 0."""
    parts = text.replace("x", ",").split(",")
    try:
        vals = [float(p) for p in parts]
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be one voxel size or three as DX,DY,DZ [mm] (e.g. 0.1 or 0.1,0.1,0.2), "
                                         f"got {text!r}") from None
    if len(vals) not in (1, 3) or not all(math.isfinite(v) and v > 0 for v in vals):
        raise argparse.ArgumentTypeError(f"must be one voxel size or three as DX,DY,DZ, each finite and > 0 [mm] "
                                         f"(e.g. 0.1 or 0.1,0.1,0.2), got {text!r}")
    return vals[0] if len(vals) == 1 else tuple(vals)


def _out_file(path, suffixes: tuple[str, ...], flag: str = "--out"):
    """``path`` as a Path when it is a file name ending in one of ``suffixes`` (not a folder)."""
    from pathlib import Path

    out = Path(path)
    if out.is_dir():
        raise MitpivError(f"{flag} {str(out)!r} is a folder; give a file name in it, e.g. {str(out / ('result' + suffixes[0]))!r}.")
    if out.suffix not in suffixes:
        raise MitpivError(f"{flag} must be a {' or '.join(suffixes)} file, got {str(out)!r}.")
    return out


def _out_dir(path, flag: str = "--out"):
    """``path`` as a Path when it is a folder or does not exist yet (not a file, and not below
    one: ``--out f/sub`` with ``f`` a file is refused before any work)."""
    from pathlib import Path

    out = Path(path)
    if out.exists() and not out.is_dir():
        raise MitpivError(f"{flag} {str(out)!r} is a file, not a folder; give a folder (it is created), "
                          f"e.g. {str(out.with_suffix(''))!r}.")
    for parent in out.parents:
        if parent.is_dir():
            break
        if parent.exists() or parent.is_symlink():
            what = "a file" if parent.exists() else "a broken link"
            raise MitpivError(f"{flag} {str(out)!r}: {str(parent)!r} is {what}, not a folder, so no folder can be "
                              f"made below it; give another folder for {flag}, or move that file away.")
    return out


def _read_mono(path, flag: str = "image"):
    """read_exr of a one-channel image; an RGB(A) or multi-channel EXR is refused."""
    from mitpiv.io import read_exr

    img, meta = read_exr(path)
    if img.ndim == 3:
        raise MitpivError(f"{flag} {str(path)!r} has {img.shape[2]} channels; mitpiv's sensor model and reconstruction "
                          f"take one-channel (luminance) images as the mono variants render them. Convert it first, "
                          f"e.g. to 0.2126 R + 0.7152 G + 0.0722 B, and write it with mitpiv.io.write_exr.")
    return img, meta


def _check_truth_frame(path, frame: int, *, need_next: bool = False):
    """The truth file's dict when ``frame`` (and with ``need_next`` the frame after it) exists."""
    from mitpiv.io import read_truth

    truth = read_truth(path)
    n = truth["positions_mm"].shape[0]
    if not 0 <= frame < n - (1 if need_next else 0):
        raise MitpivError(f"--frame {frame} is out of range: {path} holds {n} frame(s) (0 to {n - 1})"
                          + ("; PIV needs the frame after it too" if need_next else "") + ".")
    return truth


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

    _out_dir(args.out)
    files = mitpiv.render_scene(
        args.scene, out_dir=args.out, frames=args.frames, params=_parse_define(args.define), spp=args.spp, seed=args.seed,
        progress=_progress(args),
    )
    print(f"wrote {len(files)} EXR file(s) to {args.out}")
    return 0


def cmd_info(args) -> int:
    import numpy as np

    from mitpiv.io import read_exr

    img, meta = read_exr(args.file)
    nan = int(np.isnan(img).sum())
    stats = img[~np.isnan(img)]
    print(f"{args.file}: {img.shape[1]}x{img.shape[0]} float32, "
          + (f"min {stats.min():.6g}, max {stats.max():.6g}, sum {stats.sum(dtype='float64'):.6g}" if stats.size else
             "no finite pixel")
          + (f"; {nan} NaN pixel(s) of {img.size} (min, max and sum leave them out: the file holds invalid "
             f"values, which mitpiv's reconstruction refuses)" if nan else ""))
    print(json.dumps(meta, indent=2, sort_keys=True))
    return 0


def cmd_sensor(args) -> int:
    from pathlib import Path

    from mitpiv.imaging import SensorModel, apply_sensor_set
    from mitpiv.io.counts import write_counts
    from mitpiv.photometry import cameras_from_metadata, wavelength_from_metadata

    out = _out_dir(args.out)
    model = SensorModel(
        exposure=args.exposure, peak_photons=args.peak_photons, illumination_time_s=args.illumination_time,
        photometry=args.photometry, quantum_efficiency=args.qe, shot_noise=args.shot_noise,
        dark_current_e_per_s=args.dark_current, exposure_time_s=args.exposure_time, full_well_e=args.full_well,
        read_noise_e=args.read_noise, gain_e_per_count=args.gain, black_level=args.black_level,
        gaussian_noise_percent=args.noise_percent, bit_depth=args.bit_depth,
    )
    inputs = [(Path(f), *_read_mono(f)) for f in args.files]  # read everything before writing anything
    # one exposure for the whole set (scene-wide), one noise stream per (camera, frame)
    images, where = {}, {}
    keys = [(str(meta.get("sensor_id") or path.stem), int(meta.get("frame") or 0)) for path, _, meta in inputs]
    for key, (path, img, _) in zip(keys, inputs, strict=True):
        if key in images:
            raise MitpivError(f"sensor: {path} and {where[key]} are both camera {key[0]!r}, frame {key[1]}; give each "
                              f"(camera, frame) once.")
        images[key], where[key] = img, path
    for path, _, _ in inputs:
        if (out / f"{path.stem}.{args.format}").is_dir():
            raise MitpivError(f"--out: {out / f'{path.stem}.{args.format}'} is a folder where the counts of {path} "
                              f"go; choose another --out folder.")
    # all-black output (e.g. no --exposure: radiance taken as photons rounds to 0) is refused
    metas = {key[0]: meta for key, (_, _, meta) in zip(keys, inputs, strict=True)}
    cameras = None
    if args.photometry != "image" and all(isinstance(m.get("camera"), dict) for m in metas.values()):
        cameras = cameras_from_metadata(metas, photometric_f_number=args.photometric_f_number)
    res = apply_sensor_set(images, model, seed=args.seed, progress=_progress(args), on_degenerate="raise",
                           cameras=cameras, wavelength_nm=wavelength_from_metadata([m for _, _, m in inputs]))
    for key, (path, _, meta) in zip(keys, inputs, strict=True):
        target = out / f"{path.stem}.{args.format}"
        write_counts(target, res.counts[key], {**meta, "sensor_model": res.metadata(key)})
    print(f"{len(inputs)} image(s), {res.photometry} photometry, exposure {res.exposure:.4g} {res.exposure_units} "
          f"-> {out}")
    return 0


def cmd_decode(args) -> int:

    from mitpiv.lightfield import calibrate_mla, decode
    from mitpiv.render.render import write_preview

    out = _out_file(args.out, (".npz",))
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
    lf.save(out)
    # Sub-aperture mosaic preview: views tiled in (v, u) order.
    write_preview(out.with_suffix(".png"), lf.mosaic())
    s, t, u, v = lf.shape
    print(f"light field L[s, t, u, v] = {s}x{t}x{u}x{v} -> {out} (+ sub-aperture mosaic {out.with_suffix('.png')})")
    return 0


def cmd_refocus(args) -> int:
    from pathlib import Path

    import numpy as np

    from mitpiv import costs
    from mitpiv.lightfield import LightField, decode, focal_stack
    from mitpiv.render.render import write_preview

    out = _out_file(args.out, (".npy",))
    if args.z_range is not None:
        count = args.z_range[2]
        if not count.is_integer() or count < 1:
            raise MitpivError(f"--z-range: COUNT (the number of planes) must be a whole number >= 1, got {count:g}; "
                              f"e.g. --z-range -20 20 81.")
        if count > 1 and args.z_range[0] == args.z_range[1]:
            raise MitpivError(f"--z-range {args.z_range[0]:g} {args.z_range[1]:g} {count:g}: START equals STOP, so the "
                              f"{count:g} planes would all be the same; give a span (e.g. --z-range -20 20 81) or one "
                              f"plane (--z {args.z_range[0]:g}).")
        z = None
    elif args.z:
        z = np.asarray(args.z, float)
    else:
        raise MitpivError("refocus: give --z Z [Z ...] or --z-range START STOP COUNT (mm from the focal plane, + farther).")
    src = Path(args.input)
    lf = LightField.load(src) if src.suffix == ".npz" else decode(src, white=args.white)
    n_planes = z.size if z is not None else int(args.z_range[2])
    knob = f"--z-range COUNT {n_planes}" if z is None else f"--z ({n_planes} planes)"
    cost = costs.focal_stack_cost(n_planes, lf.shape[:2], n_samples_per_plane=float(np.prod(lf.shape)))
    if n_planes > costs.MAX_PLANES:
        raise MitpivError(f"refocus: {knob}: more than the {costs.MAX_PLANES} planes a focal stack may have ({cost}); a "
                          f"light field resolves depth in tens to a few thousand planes: give fewer planes, e.g. "
                          f"--z-range -20 20 81.")
    costs.check_disk(cost, out.parent, what=f"refocus: {knob}", fix="give fewer planes (--z-range COUNT) "
                     "or write --out to a larger disk")
    costs.check_memory(cost, what=f"refocus: {knob}", fix="give fewer planes")
    if z is None:
        z = np.linspace(args.z_range[0], args.z_range[1], n_planes)
    stack = focal_stack(lf, z, method=args.method, magnification=args.magnification, out=out,
                        progress=_progress(args))
    k = int(np.argmin(np.abs(z)))  # the preview: the plane nearest the focal plane
    write_preview(out.with_suffix(".png"), np.asarray(stack[k]))
    print(f"focal stack {stack.shape[0]} planes x {stack.shape[1]}x{stack.shape[2]} ({args.method}) -> {out}")
    return 0




def _grid_from_args(args):
    from mitpiv.grid import VoxelGrid

    b = args.bounds
    if not all(math.isfinite(v) for v in b) or not (b[0] < b[1] and b[2] < b[3] and b[4] < b[5]):
        raise MitpivError(f"--bounds must be finite XMIN XMAX YMIN YMAX ZMIN ZMAX [mm] with each min < max, got "
                          f"{' '.join(f'{v:g}' for v in b)}.")
    n = math.prod((hi - lo) / v for lo, hi, v in zip(b[0::2], b[1::2], _as3(args.voxel_mm), strict=True))
    if n > 2**31 - 1:
        raise MitpivError(f"--voxel-mm {args.voxel_mm} on --bounds {' '.join(f'{v:g}' for v in b)} gives {n:.3g} "
                          f"voxels, beyond the 2^31 - 1 a volume may hold (and the memory); use larger voxels or a "
                          f"smaller volume.")
    return VoxelGrid.from_bounds((b[0], b[2], b[4]), (b[1], b[3], b[5]), args.voxel_mm)


def _as3(v):
    return tuple(v) if isinstance(v, tuple | list) else (v, v, v)


def _reconstruct_inputs(paths):
    """The images (one-channel) and metadata of ``mitpiv reconstruct``: one per camera, all
    of one frame; an image given twice (the same file or the same pixels and camera) or
    images of different frames are refused."""
    import hashlib
    from pathlib import Path

    seen: dict[str, str] = {}
    for f in paths:
        key = str(Path(f).resolve())
        if key in seen:
            raise MitpivError(f"images: {f} is given {sum(str(Path(g).resolve()) == key for g in paths)} times; give "
                              f"each camera's image once (the same image twice adds no view).")
        seen[key] = f
    images, metas, digests = [], [], {}
    for f in paths:
        img, meta = _read_mono(f)
        d = hashlib.blake2b(img.tobytes() + json.dumps(meta.get("camera"), sort_keys=True).encode()).hexdigest()
        if d in digests:
            raise MitpivError(f"images: {f} and {digests[d]} are the same image (same pixels and the same camera); "
                              f"give each camera's image once.")
        digests[d] = f
        images.append(img)
        metas.append(meta)
    frames = {str(f): m.get("frame") for f, m in zip(paths, metas, strict=True) if m.get("frame") is not None}
    if len(set(frames.values())) > 1:
        listing = ", ".join(f"{f}: frame {k}" for f, k in frames.items())
        raise MitpivError(f"images: they are of different frames ({listing}); a volume is reconstructed from one "
                          f"frame's images, one per camera.")
    return images, metas


def cmd_reconstruct(args) -> int:
    import time

    import numpy as np

    from mitpiv import costs
    from mitpiv.io import write_volume
    from mitpiv.reconstruct.images import reconstruct_images, reconstruction_cost_of
    from mitpiv.render.render import write_preview

    out = _out_file(args.out, (".npz",))
    if args.min_coverage is not None and args.method != "drt-mart":
        raise MitpivError(f"--min-coverage {args.min_coverage:g} applies to --method drt-mart only (it drops voxels the "
                          f"light-field camera's ray cones barely reach); --method {args.method} would ignore it. Remove "
                          f"--min-coverage or use --method drt-mart.")
    grid = _grid_from_args(args)
    truth = _check_truth_frame(args.truth, args.frame) if args.truth else None
    images, metas = _reconstruct_inputs(args.images)
    mappings = None
    if args.calibration:  # a user's calibration instead of the true cameras of the metadata
        from mitpiv.reconstruct.mapping import mappings_from_calibration

        ids = [m.get("sensor_id") for m in metas]
        mappings = mappings_from_calibration(args.calibration, names=ids if all(ids) else None,
                                             resolution=images[0].shape[::-1])
    cost = reconstruction_cost_of(metas, grid, args.method, iterations=args.iterations,
                                  rays_per_pixel=args.rays_per_pixel)
    fix = "use larger voxels (--voxel-mm) or a smaller volume (--bounds)" + (
        ", fewer --rays-per-pixel, or a smaller light-field image (the weights grow with its pixels)"
        if args.method == "drt-mart" else "")
    costs.check_memory(cost, what=f"reconstruct: --voxel-mm {args.voxel_mm} on --bounds {' '.join(map(str, args.bounds))}",
                       fix=fix)
    logging.getLogger("mitpiv").info("grid %dx%dx%d voxels of %s mm, %d image(s), method %s", grid.shape[2],
                                     grid.shape[1], grid.shape[0], grid.voxel_mm, len(images), args.method)
    t0 = time.perf_counter()
    vol, info = reconstruct_images(images, metas, grid, args.method, whites=args.white, iterations=args.iterations,
                                   mu=args.mu, weights=args.weights, interpolation=args.interpolation,
                                   preprocess=args.preprocess, combine=args.combine,
                                   threshold_k=None if args.threshold_k < 0 else args.threshold_k,
                                   rays_per_pixel=args.rays_per_pixel, min_coverage=args.min_coverage,
                                   progress=_progress(args), mappings=mappings)
    elapsed = time.perf_counter() - t0
    metrics = {}
    if truth is not None:
        from mitpiv import analysis

        metrics = analysis.volume_quality(vol, analysis.truth_volume(truth["positions_mm"][args.frame], grid))
    record = {"method": args.method, "images": [str(f) for f in args.images], "grid": grid.to_dict(),
              "seconds": elapsed, "metrics": metrics,
              "info": {k: v for k, v in info.items() if isinstance(v, int | float | str | list)}}
    write_volume(out, vol, record)
    write_preview(out.with_suffix(".png"), np.asarray(vol).max(axis=0))
    print(f"volume {vol.shape} ({args.method}, {elapsed:.1f} s) -> {out} (+ max projection {out.with_suffix('.png')})")
    for k, v in metrics.items():
        print(f"  {k:4s} {v:.4f}")
    return 0


def cmd_evaluate(args) -> int:

    from mitpiv import analysis
    from mitpiv.io.records import write_json

    out_path = _out_file(args.out, (".json",)) if args.out else None
    from mitpiv.io import read_volume

    truth = _check_truth_frame(args.truth, args.frame)
    vol, grid, _ = read_volume(args.volume)
    metrics, res = analysis.evaluate_volume(vol, grid, truth["positions_mm"][args.frame], method=args.method,
                                            threshold_rel=args.threshold_rel, radius_voxels=args.radius_voxels,
                                            threshold_of=args.threshold_of)
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

    from mitpiv import analysis, costs

    out = _out_file(args.out, (".npz",))
    from mitpiv.io import read_volume

    truth = _check_truth_frame(args.truth, args.frame, need_next=True) if args.truth else None

    va, grid, _ = read_volume(args.vol_a)
    vb, grid_b, _ = read_volume(args.vol_b)
    if grid_b != grid:
        raise MitpivError(f"piv: the volumes lie on different grids ({grid.to_dict()} vs {grid_b.to_dict()}); "
                          f"reconstruct both frames on the same --bounds and --voxel.")
    windows = args.windows
    nz, ny, nx = grid.shape
    for w in windows:
        wx, wy, wz = w if isinstance(w, tuple) else (w, w, w)
        if wx > nx or wy > ny or wz > nz:
            raise MitpivError(f"--windows {'x'.join(map(str, (wx, wy, wz)))} does not fit the volume of {nx}x{ny}x{nz} "
                              f"voxels (x, y, z); give windows no larger than the volume.")
    costs.check_memory(costs.piv_cost(grid.shape, windows, args.overlap),
                       what=f"piv: --windows {' '.join(map(str, args.windows))} --overlap {args.overlap}",
                       fix="use a smaller --overlap or larger --windows")
    dt, flow, t0 = args.dt_s, None, 0.0
    if truth is not None:
        from mitpiv.physics.flows import flow_from_dict

        if not truth["flow"]:
            raise MitpivError(f"piv: {args.truth} names no analytic flow; velocity errors need one.")
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
    empty = [str(p) for p, v in ((args.vol_a, va), (args.vol_b, vb)) if not v.any()]
    outliers = (f"outliers n/a: {' and '.join(empty)} {'is' if len(empty) == 1 else 'are'} empty (every voxel 0), "
                f"nothing to correlate; check the reconstruction" if empty
                else f"outliers {100 * field.outlier_ratio:.2f} %")
    print(f"{field.n_vectors} vectors {field.shape[::-1]} (x, y, z), {field.info['seconds']:.1f} s, "
          f"{outliers}, invalid {field.info['invalid']} -> {out}")
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
    _out_dir(args.out)
    result = run_experiment(args.experiment, args.out, overrides=overrides, until=args.until,
                            progress=_progress(args))
    if args.until is not None:
        print(f"{result.name}: stopped after the {args.until} stage ({', '.join(result.stages)}) -> {args.out}")
        return 0
    print(f"{result.headline()} -> {args.out}/report/report.md")
    return 0


def cmd_preview(args) -> int:
    from mitpiv.studies.preview import preview

    _out_dir(args.out)
    res = preview(args.path, args.out, volume_mm=args.volume, params=_parse_define(args.define) or None,
                  overrides=_run_overrides(args) or None)
    print(f"{args.path}: rig.png, views.png, rig.vtu, rig.json -> {args.out}"
          + (f" ({len(res['warnings'])} warning(s) above)" if res["warnings"] else ""))
    if res["refused"]:
        print("mitpiv preview: no point of the volume is seen by every camera; 'mitpiv run' refuses it (exit "
              "status 1).", file=sys.stderr)
        return 1
    return 0


def cmd_schema(args) -> int:
    from mitpiv.studies.kinds import get_kind
    from mitpiv.studies.schema import describe

    kind = get_kind(args.kind, source="schema")
    print(describe(kind.schema, title=f"Experiment kind {kind.name!r}: {kind.describe}"))
    return 0


def cmd_sweep(args) -> int:
    from mitpiv.studies import run_sweep

    _out_dir(args.out)
    if args.scheduler is not None:
        _check_scheduler(args.scheduler)
    df = run_sweep(args.study, args.out, scheduler=args.scheduler, workers=args.workers, full=args.full,
                   progress=_progress(args))
    ok = int((df["status"] == "ok").sum())
    print(f"{ok}/{len(df)} points ok -> {args.out}/results.csv, results.parquet")
    if args.tracking_results:
        from mitpiv.replications.tracking_density.study import write_tracking_study

        doc = write_tracking_study(args.out, args.tracking_results)
        for r in doc["rows"]:
            vals = " ".join(f"{k}={r[k]:.4g}" if isinstance(r[k], float) else f"{k}={r[k]}"
                            for k in ("ppp", "yield", "ghost_fraction", "position_error_px", "velocity_error", "wall_s"))
            print(f"  {r['method']:12s} {vals}" + (f"  [{r['error']}]" if r["error"] else ""))
        print(f"wrote {args.tracking_results}/results.json and {len(doc['figures'])} figures")
    failed = df[df["status"] != "ok"]
    for _, row in failed.iterrows():
        print(f"  failed {row['point']}: {row['error']}")
    if len(failed):  # a sweep with failed points is not a success (a rerun runs only those)
        print(f"mitpiv: error: {len(failed)} of {len(df)} points failed (listed above); fix them and rerun the "
              f"sweep: the finished points are kept.", file=sys.stderr)
        return 1
    return 0


def _check_scheduler(address: str, timeout_s: float = 3.0) -> None:
    """Refuse a --scheduler address that is malformed or where nothing answers within ``timeout_s``."""
    import socket
    from urllib.parse import urlsplit

    text = address if "://" in address else f"tcp://{address}"
    try:
        u = urlsplit(text)
        host, port = u.hostname, u.port
    except ValueError:
        host = port = None
    if u.scheme not in ("tcp", "tls", "ws", "wss") or not host or port is None:
        raise MitpivError(f"--scheduler must be a Dask scheduler address HOST:PORT or tcp://HOST:PORT, got "
                          f"{address!r}; or leave it out for a local cluster.")
    try:
        with socket.create_connection((host, port), timeout=timeout_s):
            pass
    except OSError as e:
        raise MitpivError(f"--scheduler {address}: nothing answers there within {timeout_s:g} s "
                          f"({e.strerror or type(e).__name__}); start the scheduler (dask scheduler) or leave "
                          f"--scheduler out for a local cluster.") from None


def cmd_export(args) -> int:
    if not (args.vtk or args.openlpt or args.openptv or args.davis or args.tiff):
        print("mitpiv: error: export: choose a format: --vtk (ParaView / VTK files), --openlpt DIR or --openptv DIR "
              "(tracker inputs), --davis DIR (LaVision DaVis sets), --tiff DIR (image frames for any PIV code).",
              file=sys.stderr)
        return 2
    for flag, out in (("--out", args.out), ("--openlpt", args.openlpt), ("--openptv", args.openptv),
                      ("--davis", args.davis), ("--tiff", args.tiff)):
        if out is not None:  # every output folder checked before anything is exported
            _out_dir(out, flag)
    if args.tiff:
        from mitpiv.studies.export import export_images

        m = export_images(args.run, args.tiff, progress=_progress(args))
        print(f"tiff: {len(m['sensors'])} cameras x {len(m['frames'])} frames ({m['source']} images, {m['bits']}-bit, "
              f"gain {m['gain']:.6g}) -> {args.tiff}")
        if not (args.vtk or args.openlpt or args.openptv or args.davis):
            return 0
    if args.davis:
        from mitpiv.studies.export_davis import export_davis

        m = export_davis(args.run, args.davis, progress=_progress(args), n_planes=max(args.plate_planes, 1),
                         spp=args.plate_spp, calibration=args.plate_planes > 0)
        cal = m.get("calibration")
        print(f"davis: {len(m['sensors'])} cameras x {len(m['times_s'])} frames ({m['source']} images, "
              f"{m['images']['dtype']})" + (f", calibration plate at {len(cal['z_positions_mm'])} z positions"
                                            if cal else "") + f" -> {args.davis}")
        if not (args.vtk or args.openlpt or args.openptv):
            return 0
    if args.openlpt or args.openptv:
        from mitpiv.studies.export import export_tracker_inputs

        for tool, out in (("openlpt", args.openlpt), ("openptv", args.openptv)):
            if out:
                opts = {"undistort": True} if tool == "openlpt" and args.undistort else {}
                m = export_tracker_inputs(args.run, out, tool=tool, progress=_progress(args), **opts)
                print(f"{tool}: {m['n_cameras']} cameras x {m['n_frames']} frames ({m['source']} images, "
                      f"{m['bits']}-bit, gain {m['gain']:.6g}; settings {m.get('settings_from', 'given')}"
                      f"{' from the run' if m.get('settings_from', '').startswith('derived') else ''}"
                      f") -> {out}")
        if not args.vtk:
            return 0
    from mitpiv.studies.export import export_vtk

    files = export_vtk(args.run, args.out, progress=_progress(args))
    print(f"{len(files)} VTK files -> {files[-1].parent} (open {files[-1].name} in ParaView)")
    return 0


def cmd_score(args) -> int:
    from mitpiv.studies.score import score

    if args.out is not None:
        _out_dir(args.out)
    m = score(args.run, args.result, out_dir=args.out, what=args.what, fmt=args.format, camera=args.camera,
              frames=args.frames, window=args.window, length_unit=args.length_unit, velocity_unit=args.velocity_unit,
              flip_y=args.flip_y, plane_z_mm=args.plane_z_mm, radius_mm=args.radius_mm, first_frame=args.first_frame,
              group=args.group, davis_frame=args.davis_frame, reference=args.reference, force=args.force)

    def f(x, spec=".4g"):
        return "n/a" if x is None else (", ".join(format(v, spec) for v in x) if isinstance(x, list) else format(x, spec))

    if m["kind"] == "vectors-2d":
        line = (f"{m['n_scored']} vectors on {m['camera']}: RMS error {f(m['rms_px'])} px (x, y; {m['reference']} "
                f"reference), "
                f"{f(m['error_outlier_fraction'], '.2%')} above {m['error_outlier_px']:g} px")
    elif m["kind"] == "vectors-3d":
        line = (f"{m['n']} vectors: RMS error {f(m['rms_vox'])} voxels (x, y, z), "
                f"{f(m['error_outlier_fraction'], '.2%')} above {m['error_outlier_vox']:g} voxel")
    else:
        line = (f"{m['kind']}: yield {f(m['yield'], '.2%')}, ghosts {f(m['ghost_fraction'], '.2%')}, position error "
                f"{f(m['position_error_mm'])} mm")
    flagged = f" (FLAGGED: {len(m['flags'])} check(s) failed, scored with --force)" if m["flags"] else ""
    print(f"{line}{flagged} -> {os.path.dirname(m['files'][0])}/score.md")
    return 0


def cmd_bench(args) -> int:
    from mitpiv.studies.accuracy import accuracy_time

    _out_dir(args.out)
    stages = [s.strip() for s in args.stages.split(",")] if args.stages else None
    accuracy_time(args.out, size="quick" if args.quick else "full", stages=stages, seed=args.seed)
    print(f"wrote {args.out}/accuracy_time.md, accuracy_time.csv and pareto_*.png")
    return 0


def cmd_replicate(args) -> int:
    from mitpiv.replications.frame import Row, get_study, list_studies, reclassify, replicate, tally_line

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
    out = args.out or f"out/replicate/{args.study}{'-quick' if args.quick else ''}"
    if args.reclassify:
        if args.quick or args.allow_mixed or args.seed or args.workers != 1:
            raise MitpivError("replicate --reclassify rewrites the results already in --out without computing "
                              "anything; drop --quick, --seed, --workers and --allow-mixed.")
        res = reclassify(args.study, out)
    else:
        if args.out is not None:
            _out_dir(args.out)
        res = replicate(args.study, args.out, quick=args.quick, seed=args.seed, workers=args.workers,
                        progress=_progress(args), allow_mixed=args.allow_mixed)
    rows = [Row.from_dict(r) for r in res["rows"]]
    print(f"{args.study} ({res['scale']}): {tally_line(rows).replace('**', '')}; {res['wall_s']:.0f} s "
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
    p = _Parser(prog="mitpiv", description="Physically based rendering testbed for volumetric PIV.")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress bars or progress messages")
    p.add_argument("--verbose", "-v", action="store_true", help="debug messages (every step of long loops)")
    sub = p.add_subparsers(dest="command", required=True)
    r = sub.add_parser("render", help="render every sensor of a scene XML for each frame to EXR + PNG")
    r.add_argument("scene", help="scene XML file")
    r.add_argument("--out", required=True, help="output folder")
    r.add_argument("--frames", type=_int_in(0), nargs="+", default=[0, 1], help="frames to render (default: 0 1)")
    r.add_argument("-D", dest="define", action="append", metavar="NAME=VALUE", help="scene parameter ($NAME)")
    r.add_argument("--spp", type=int, default=None, help="samples per pixel (camera-tracing integrators)")
    r.add_argument("--seed", type=_seed, default=0, help="experiment seed, in [0, 2**63)")
    r.set_defaults(func=cmd_render)
    i = sub.add_parser("info", help="print an EXR file's mitpiv metadata")
    i.add_argument("file")
    i.set_defaults(func=cmd_info)
    s = sub.add_parser("sensor", help="apply the camera sensor model to rendered EXRs, write integer images")
    s.add_argument("files", nargs="+", help="rendered EXR files")
    s.add_argument("--out", required=True, help="output folder")
    s.add_argument("--format", choices=["png", "tif", "exr"], default="png", help="png/tif: 8/16-bit for PIV software; exr: uint + metadata")
    s.add_argument("--bit-depth", type=int, default=12, help="8, 10, 12, 14 or 16 (default 12)")
    s.add_argument("--exposure", type=float, default=None,
                   help="photons per pixel per unit of the exposed quantity (per W collected with aperture photometry, "
                        "per unit of image value with --photometry image)")
    s.add_argument("--peak-photons", type=float, default=None, help="alternative: photons in the brightest pixel")
    s.add_argument("--illumination-time", type=float, default=None,
                   help="alternative: photons from physics, the time [s] the sheet lights the particles (pulse "
                        "duration); the scene rendered at the sheet's real irradiance")
    s.add_argument("--photometry", choices=["auto", "aperture", "image"], default="auto",
                   help="aperture: each camera's counts follow its aperture (pixel value x pixel etendue); image: the "
                        "pixel values are exposed as they are; auto (default): aperture when every camera states one")
    s.add_argument("--photometric-f-number", type=float, default=None,
                   help="f-number for the pinhole cameras that state no aperture (aperture photometry)")
    s.add_argument("--qe", type=float, default=1.0, help="quantum efficiency (0, 1]")
    s.add_argument("--shot-noise", action="store_true", help="Poisson photon noise")
    s.add_argument("--dark-current", type=float, default=0.0, help="dark electrons per second")
    s.add_argument("--exposure-time", type=float, default=0.0, help="exposure time [s] (for dark current)")
    s.add_argument("--full-well", type=float, default=None, help="full-well capacity [e-]")
    s.add_argument("--read-noise", type=float, default=0.0, help="read noise [e- RMS]")
    s.add_argument("--gain", type=float, default=1.0, help="electrons per count")
    s.add_argument("--black-level", type=float, default=0.0, help="offset [counts]")
    s.add_argument("--noise-percent", type=float, default=0.0, help="white Gaussian noise, %% of the peak")
    s.add_argument("--seed", type=_seed, default=0, help="noise seed, in [0, 2**63)")
    s.set_defaults(func=cmd_sensor)
    d = sub.add_parser("decode", help="decode a raw plenoptic EXR into a 4D light field (.npz) + sub-aperture mosaic")
    d.add_argument("raw", help="raw EXR rendered by a plenoptic sensor")
    d.add_argument("--out", required=True, help="output .npz")
    d.add_argument("--white", default=None, help="white EXR: devignetting and view weights")
    d.add_argument("--calibrate", action="store_true", help="calibrate the MLA from --white instead of using the metadata")
    d.add_argument("--layout", choices=["rect", "hex"], default=None, help="MLA layout for --calibrate")
    d.add_argument("--interpolation", choices=["nearest", "linear", "cubic"], default="linear")
    d.add_argument("--angular-oversample", type=_int_in(1, 8), default=1, help="views per lenslet pitch (1..8)")
    d.set_defaults(func=cmd_decode)
    f = sub.add_parser("refocus", help="focal stack of a light field (.npz) or raw EXR, streamed to a .npy file")
    f.add_argument("input", help="light field .npz (mitpiv decode) or raw EXR")
    f.add_argument("--out", required=True, help="output .npy (n_z, n_t, n_s)")
    f.add_argument("--z", type=_float_in(), nargs="+", help="depths [mm] from the focal plane (+ = farther)")
    f.add_argument("--z-range", type=_float_in(), nargs=3, metavar=("START", "STOP", "COUNT"),
                   help="COUNT planes from START to STOP [mm]")
    f.add_argument("--method", choices=["additive", "multiplicative"], default="additive")
    f.add_argument("--magnification", choices=["natural", "constant"], default="natural")
    f.add_argument("--white", default=None, help="white EXR (raw-EXR input only)")
    f.set_defaults(func=cmd_refocus)
    c = sub.add_parser("reconstruct", help="reconstruct a volume from camera EXRs (tomographic, SAPIV or plenoptic)")
    c.add_argument("images", nargs="+", help="EXR images with camera metadata (one per camera)")
    c.add_argument("--out", required=True, help="output .npz (volume (n_z, n_y, n_x) + JSON meta)")
    c.add_argument("--method", choices=RECONSTRUCT_METHODS, default="mart")
    c.add_argument("--bounds", type=_float_in(), nargs=6, required=True, metavar=("XMIN", "XMAX", "YMIN", "YMAX", "ZMIN", "ZMAX"),
                   help="volume [mm]")
    c.add_argument("--voxel-mm", "--voxel", dest="voxel_mm", type=_voxel, required=True,
                   help="voxel size [mm]: one (cubic) or three as DX,DY,DZ (--voxel: deprecated)")
    c.add_argument("--iterations", type=_int_in(0, MAX_ITERATIONS), default=5,
                   help=f"MART / SMART / DRT-MART iterations (0..{MAX_ITERATIONS})")
    c.add_argument("--mu", type=_float_in(0, 2, lo_open=True, hi_open=True), default=1.0, help="MART relaxation (0, 2)")
    c.add_argument("--weights", choices=["circle", "gaussian"], default="circle")
    c.add_argument("--interpolation", choices=["linear", "cubic"], default="linear")
    c.add_argument("--preprocess", type=_float_in(), default=None, metavar="K", help="histogram threshold: background + K sigma")
    c.add_argument("--combine", choices=["additive", "multiplicative"], default="multiplicative",
                   help="sapiv / plenoptic combination")
    c.add_argument("--threshold-k", type=_float_in(), default=3.0, help="sapiv: keep mean + k sigma per plane (< 0: none)")
    c.add_argument("--white", nargs="+", default=None, help="plenoptic: white EXR per image")
    c.add_argument("--rays-per-pixel", type=_int_in(1, 4096), default=16, help="drt-mart ray bundle per pixel")
    c.add_argument("--min-coverage", type=_float_in(0.0, 1.0, lo_open=True, hi_open=True), default=None,
                   help="drt-mart: drop the voxels at the edge of the field whose ray cones the sensor catches less than "
                   "this share of (e.g. 0.75; default: keep all)")
    c.add_argument("--truth", default=None, help="truth .npz: print Q, Q*, Q' and SNR")
    c.add_argument("--frame", type=_int_in(0), default=0, help="truth frame of the images")
    c.add_argument("--calibration", default=None, help="DLT / polynomial table (.csv, .json): map through it, not the "
                   "metadata's cameras (cameras by the images' sensor ids)")
    c.set_defaults(func=cmd_reconstruct)
    e = sub.add_parser("evaluate", help="find particles in a reconstructed volume, match them to the truth, print errors")
    e.add_argument("volume", help="volume .npz from 'mitpiv reconstruct'")
    e.add_argument("--truth", required=True, help="truth .npz (particle positions per frame)")
    e.add_argument("--frame", type=_int_in(0), default=0, help="truth frame of the volume")
    e.add_argument("--method", choices=["gauss3", "centroid", "lsq"], default="gauss3", help="sub-voxel localisation")
    e.add_argument("--threshold-rel", type=_float_in(0, 1, hi_open=True), default=0.1,
                   help="peaks above this fraction of the --threshold-of level")
    e.add_argument("--threshold-of", choices=("robust", "max"), default="robust",
                   help="the level --threshold-rel is a fraction of: 'robust' (the 99.99th percentile of the local "
                        "maxima, at least the 50th brightest; default) or 'max' (the brightest voxel)")
    e.add_argument("--radius-voxels", type=_float_in(0, lo_open=True), default=2.0, help="matching search radius [voxels]")
    e.add_argument("--out", default=None, help="metrics .json (+ error PDF plot .png)")
    e.set_defaults(func=cmd_evaluate)
    v = sub.add_parser("piv", help="multi-pass 3D cross-correlation between two reconstructed volumes")
    v.add_argument("vol_a", help="volume .npz of the first frame")
    v.add_argument("vol_b", help="volume .npz of the second frame")
    v.add_argument("--out", required=True, help="vector field .npz")
    v.add_argument("--windows", type=_window, nargs="+", default=[64, 48, 32],
                   help="window per pass: N (cubic) or WXxWYxWZ (default 64 48 32)")
    v.add_argument("--overlap", type=_float_in(0, 1, hi_open=True), default=0.75, help="window overlap fraction [0, 1)")
    v.add_argument("--no-deform", action="store_true", help="integer window shifting instead of window deformation")
    v.add_argument("--interpolation", choices=["linear", "cubic"], default="cubic", help="deformation resampling")
    v.add_argument("--normalised", action="store_true", help="normalised cross-correlation")
    v.add_argument("--threshold", type=_float_in(0, lo_open=True), default=2.0, help="universal outlier detection threshold")
    v.add_argument("--replace", choices=["median", "interpolation", "none"], default="median")
    v.add_argument("--dt-s", "--dt", dest="dt_s", type=_float_in(0, lo_open=True), default=None,
                   help="time between the frames [s]: velocities in mm/s (--dt: deprecated)")
    v.add_argument("--truth", default=None, help="truth .npz with the flow: velocity error against it")
    v.add_argument("--frame", type=_int_in(0), default=0, help="truth frame of vol_a")
    v.set_defaults(func=cmd_piv)
    x = sub.add_parser("run", help="run (or resume) an experiment TOML: render, reconstruct, evaluate, PIV, report")
    x.add_argument("experiment", help="experiment .toml")
    need = x.add_mutually_exclusive_group(required=True)  # a run folder, or --check alone
    need.add_argument("--out", default=None, metavar="DIR",
                      help="run folder, required unless --check (stages resume when rerun)")
    need.add_argument("--check", action="store_true", help="validate the experiment (every table) and run nothing")
    x.add_argument("--until", default=None, metavar="STAGE", help="stop after this stage (e.g. render or sensor: "
                   "the images alone, for processing in another tool; 'mitpiv score' scores its result)")
    x.add_argument("--set", action="append", metavar="TABLE.FIELD=VALUE",
                   help="set any experiment field (a TOML value), e.g. --set piv.windows=[48,32]; see 'mitpiv schema'")
    for flag, key in RUN_FLAGS.items():
        x.add_argument(f"--{flag}", **_flag_kwargs(key))
    x.set_defaults(func=cmd_run)
    pv = sub.add_parser("preview", help="draw a scene's or an experiment's rig (cameras, laser sheet, volume) before "
                        "any render: rig.png, views.png, rig.vtu; warn as 'run --check' does")
    pv.add_argument("path", help="scene XML or experiment TOML")
    pv.add_argument("--out", required=True, metavar="DIR", help="output folder")
    pv.add_argument("--volume", type=_float_in(), nargs=6, default=None, metavar=("X0", "X1", "Y0", "Y1", "Z0", "Z1"),
                    help="scene XML: the measurement volume [mm] (an experiment gives its own)")
    pv.add_argument("-D", dest="define", action="append", metavar="NAME=VALUE", help="scene XML: parameter ($NAME)")
    pv.add_argument("--set", action="append", metavar="TABLE.FIELD=VALUE",
                    help="experiment: set any field, e.g. --set scene.params.resolution=256")
    pv.set_defaults(func=cmd_preview)
    sc = sub.add_parser("schema", help="print every experiment table and field with its unit, default and range")
    sc.add_argument("--kind", default="tomo", help="experiment kind: tomo (default), backlit or tracking")
    sc.set_defaults(func=cmd_schema)
    w = sub.add_parser("sweep", help="run a parameter study (grid or list of experiment overrides) on Dask")
    w.add_argument("study", help="study .toml")
    w.add_argument("--out", required=True, help="sweep folder (results table, one run folder per point)")
    w.add_argument("--scheduler", default=None, help="address of a running Dask scheduler (default: a local cluster)")
    w.add_argument("--workers", type=_int_in(1, 512), default=None, help="local cluster worker processes (default 2)")
    w.add_argument("--full", action="store_true", help="the full-size study (the study's [full] overrides)")
    w.add_argument("--tracking-results", default=None, metavar="DIR", help="a tracking study: write results.json "
                   "(one row per method and density) and a figure per metric against ppp into DIR")
    w.set_defaults(func=cmd_sweep)
    ex = sub.add_parser("export", help="export a finished run folder for other tools (--vtk: ParaView files; "
                        "--openlpt / --openptv: inputs of those trackers)")
    ex.add_argument("run", help="run folder of 'mitpiv run'")
    ex.add_argument("--vtk", action="store_true", help="volumes (.vti), PIV field (.vts), particles and tracks (.vtu), "
                    "run.pvd")
    ex.add_argument("--out", default=None, help="output folder (default RUN/vtk)")
    ex.add_argument("--openlpt", default=None, metavar="DIR", help="OpenLPT STB inputs (config, camera files, TIFFs)")
    ex.add_argument("--openptv", default=None, metavar="DIR", help="OpenPTV inputs (parameters, .ori/.addpar, TIFFs)")
    ex.add_argument("--davis", default=None, metavar="DIR", help="LaVision DaVis: image set with frame times, "
                    "calibration-plate image set, truth particle field (lvpyio)")
    ex.add_argument("--plate-planes", type=_int_in(0), default=5, metavar="N", help="--davis: calibration-plate "
                    "positions through the seeding box's depth (default 5; 0: no calibration set)")
    ex.add_argument("--plate-spp", type=_int_in(1), default=4, metavar="N", help="--davis: samples per (film) pixel "
                    "of the plate renders (default 4; their cost: mitpiv.studies.export_davis)")
    ex.add_argument("--tiff", default=None, metavar="DIR", help="16-bit TIFF frames of every camera for any 2-D PIV "
                    "code (<sensor>_<frame>.tif; the camera counts as they are)")
    ex.add_argument("--undistort", action="store_true", help="--openlpt: resample distorted cameras' frames to "
                    "undistorted pinhole images (openlpt 2.2.4 cannot stereo-match distorted cameras)")
    ex.set_defaults(func=cmd_export)
    so = sub.add_parser("score", help="score another tool's result (a 2-D or 3-D vector field, particles or tracks) "
                        "against a run's truth with mitpiv's own metrics")
    so.add_argument("run", help="run folder of 'mitpiv run' (its truth and cameras)")
    so.add_argument("result", help="the tool's result: DaVis .vc7/.set, OpenPIV .txt, .csv, .npz, .h5; OpenLPT or "
                    "OpenPTV result folders; particle CSV (frame, x, y, z[, track])")
    so.add_argument("--out", default=None, help="output folder (default RESULT_score beside the result)")
    so.add_argument("--what", choices=["vectors", "particles"], default=None, help="what the result holds (default: "
                    "from its format)")
    so.add_argument("--format", default=None, choices=["davis", "openpiv", "csv", "npz", "hdf5", "openlpt", "openptv"],
                    help="the result's format (default: from its name)")
    so.add_argument("--camera", default=None, help="a 2-D field: the camera it was measured on (default the run's first)")
    so.add_argument("--frames", type=_int_in(0), nargs=2, default=[0, 1], metavar=("A", "B"),
                    help="the run frames of the field's two images (default 0 1)")
    so.add_argument("--window", type=float, default=None, help="vector fields: the interrogation window's side in the "
                    "field's length unit (the truth is averaged over it)")
    so.add_argument("--length-unit", default=None, help="positions' unit where the file does not say: px, mm, m, cm, um")
    so.add_argument("--velocity-unit", default=None, help="vectors' unit where the file does not say: displacements "
                    "px, vox, mm, m or velocities px/s, mm/s, m/s")
    so.add_argument("--flip-y", action="store_true", help="the field's y axis points up (OpenPIV's "
                    "transform_coordinates): mirror y and negate v")
    so.add_argument("--plane-z-mm", type=float, default=None, help="a 2-D field: the world plane z it lies on "
                    "(default the laser sheet's mid-plane, else the volume's middle)")
    so.add_argument("--radius-mm", type=float, default=None, help="particles: the match radius (default the run's own)")
    so.add_argument("--first-frame", type=_int_in(0), default=0, help="particles: the run frame of the result's first "
                    "frame (default 0)")
    so.add_argument("--group", default=None, help="HDF5: the group holding x, y, z, u, v, w")
    so.add_argument("--davis-frame", type=_int_in(0), default=0, help="DaVis vector set: the frame to score")
    so.add_argument("--reference", choices=["flow", "particles"], default=None, help="a 2-D field's window-averaged "
                    "truth: the flow on the sheet (default with an analytic flow) or the true particles in each window")
    so.add_argument("--force", action="store_true", help="score a result that fails the unit / axis / frame checks "
                    "(the flags are recorded)")
    so.set_defaults(func=cmd_score)
    b = sub.add_parser("bench", help="benchmarks: 'accuracy-time' measures every accuracy knob's time and error")
    b.add_argument("which", choices=["accuracy-time"], help="the benchmark to run")
    b.add_argument("--out", default="out/accuracy-time", help="output folder (tables, CSV, Pareto plots)")
    b.add_argument("--quick", action="store_true", help="the small preset (seconds; default: the full preset, ~15 min)")
    b.add_argument("--stages", default=None,
                   help="comma-separated subset of render,lightfield,reconstruct,piv,end_to_end (default all)")
    b.add_argument("--seed", type=_seed, default=0, help="seed of the particle field, in [0, 2**63)")
    b.set_defaults(func=cmd_bench)
    rp = sub.add_parser("replicate", help="replicate a published study (the paper's set-up and measures, "
                        "results side by side)")
    rp.add_argument("study", nargs="?", default=None, help="study name (see --list)")
    rp.add_argument("--list", action="store_true", help="list the replications and their papers")
    rp.add_argument("--quick", action="store_true", help="the reduced study (minutes; same code and row ids)")
    rp.add_argument("--out", default=None, help="output folder (default out/replicate/NAME[-quick]); resumes")
    rp.add_argument("--seed", type=_seed, default=0, help="base seed of every random stream, in [0, 2**63)")
    rp.add_argument("--workers", type=_int_in(1, 512), default=1, help="local Dask worker processes for independent points")
    rp.add_argument("--allow-mixed", action="store_true",
                    help="let full-scale results use cached points computed at other commits (said in the report)")
    rp.add_argument("--reclassify", action="store_true",
                    help="apply the study's current row kinds to the results already in --out, computing nothing")
    rp.set_defaults(func=cmd_replicate)
    try:
        args = p.parse_args(argv)
    except _UsageError as e:
        print(f"mitpiv: error: {e}", file=sys.stderr)
        return 2
    from mitpiv.progress import set_quiet

    if args.quiet:
        set_quiet(True)
    level = logging.WARNING if args.quiet else (logging.DEBUG if args.verbose else logging.INFO)
    logging.basicConfig(level=level, format="%(message)s", stream=sys.stderr)
    logging.getLogger("mitpiv").setLevel(level)
    for noisy in ("distributed", "numba", "matplotlib", "PIL"):  # other libraries stay at warnings
        logging.getLogger(noisy).setLevel(max(level, logging.WARNING))
    _plain_warnings()
    from tqdm.contrib.logging import logging_redirect_tqdm

    previous = _stop_on_sigterm()
    try:
        with logging_redirect_tqdm(loggers=[logging.root]):  # messages print above the bars (once: via the root)
            return args.func(args)
    except (MitpivError, _UsageError) as e:
        print(f"mitpiv: error: {e}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, _Terminated) as e:
        # the unwinding removed the unfinished stage's temporary files and released the lock
        sig = "SIGTERM" if isinstance(e, _Terminated) else "Ctrl-C"
        print(f"mitpiv: stopped by {sig}; finished stages are kept (a rerun resumes), temporary files were "
              f"removed.", file=sys.stderr)
        return 143 if isinstance(e, _Terminated) else 130
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


def _plain_warnings() -> None:
    """mitpiv's own warnings (:class:`~mitpiv.errors.MitpivWarning`) print as one
    ``mitpiv: warning: ...`` line, without Python's file and source-line decoration; the
    warnings of other libraries keep Python's form. Only the formatting changes (installed
    once per process): a caller that records warnings (``warnings.catch_warnings(record=True)``,
    pytest) still records them."""
    import warnings

    from mitpiv.errors import MitpivWarning

    default = warnings.formatwarning
    if getattr(default, "mitpiv", False):
        return

    def plain(message, category, filename, lineno, line=None):
        if issubclass(category, MitpivWarning):
            return f"mitpiv: warning: {message}\n"
        return default(message, category, filename, lineno, line)

    plain.mitpiv = True
    warnings.formatwarning = plain


class _Terminated(BaseException):
    """SIGTERM, raised in the main thread so that every ``finally`` runs (temporary stage
    folders and files are removed, the run folder's lock released)."""


def _stop_on_sigterm():
    """Turn SIGTERM into :class:`_Terminated` (main thread only); returns the old handler."""
    import threading

    if threading.current_thread() is not threading.main_thread():
        return None

    def handler(signum, frame):
        raise _Terminated()

    return signal.signal(signal.SIGTERM, handler)


if __name__ == "__main__":
    sys.exit(main())
