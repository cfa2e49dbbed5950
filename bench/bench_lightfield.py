"""Light-field benchmark: focal-stack cost per plane and per raw megapixel against a
straightforward baseline (scipy.ndimage.shift per view, then the mean), in the same run,
and the accuracy knobs (decode interpolation, (u, v) supersampling, number of planes) with
time and error of the depth found for a particle.

``python bench/bench_lightfield.py`` (quick, ~1 min); ``--full`` also streams a 1000-plane
focal stack of a 6600x4400 raw image (PMR 14, hex) to disk.
"""

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy import ndimage

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import mitpiv  # noqa: E402,F401
from mitpiv import lightfield as lfm  # noqa: E402
from mitpiv.physics.plenoptic import PlenopticCamera  # noqa: E402


def baseline_plane(lf, alpha):
    """Shift-and-add with scipy.ndimage.shift, one view at a time."""
    o = lf.optics
    k = -o.image_distance_mm / o.gap_mm * o.image_scale
    ds = lf.s_px[1] - lf.s_px[0]
    dt = lf.t_px[1] - lf.t_px[0]
    acc = np.zeros(lf.data.shape[2:])
    wsum = 0.0
    for iv in range(lf.data.shape[0]):
        for iu in range(lf.data.shape[1]):
            w = lf.view_weights[iv, iu]
            if w <= 0:
                continue
            sh = (1 - 1 / alpha) * k * np.array([lf.du_px[iv] / dt, lf.du_px[iu] / ds])
            acc += w * ndimage.shift(lf.data[iv, iu], -sh, order=1, mode="constant")
            wsum += w
    return acc / wsum


def synthetic_lf(cam, seed=0):
    rng = np.random.default_rng(seed)
    raw = rng.uniform(0, 1, (cam.resolution[1], cam.resolution[0])).astype(np.float32)
    return lfm.decode(raw, optics=cam)


def main():
    from mitpiv.render.variant import ensure_variant

    ensure_variant()  # Mitsuba objects below (importing mitpiv selects no variant)
    ap = argparse.ArgumentParser()
    ap.add_argument("--full", action="store_true")
    args = ap.parse_args()
    print("== focal stack: mitpiv kernel vs scipy.ndimage.shift baseline (same light field, additive)")
    for n, pmr in ((800, 14), (1600, 14), (1600, 7)):
        cam = PlenopticCamera(resolution=(n, n), pixel_pitch_um=5.5, focal_length_mm=50, f_number=2.8,
                              focus_distance_mm=250, mla_pitch_um=5.5 * pmr, mla_layout="hex")
        lf = synthetic_lf(cam)
        z = np.linspace(-20, 20, 21)
        lfm.focal_stack(lf, z[:1])  # compile
        t0 = time.perf_counter()
        st = lfm.focal_stack(lf, z)
        t_ours = (time.perf_counter() - t0) / len(z)
        alphas = lfm.alpha_from_z(z[:3], focal_length_mm=50, magnification=cam.magnification)
        t0 = time.perf_counter()
        base = [baseline_plane(lf, a) for a in alphas]
        t_base = (time.perf_counter() - t0) / 3
        o = lf.optics
        shift = np.abs(1 - 1 / alphas).max() * o.image_distance_mm / o.gap_mm * o.image_scale * np.abs(lf.du_px).max()
        mg = int(np.ceil(shift / (lf.t_px[1] - lf.t_px[0]))) + 2  # compare where every view lands inside
        inner = (slice(mg, -mg), slice(mg, -mg))
        err = max(np.abs(st[k][inner] - base[k][inner]).max() for k in range(3))
        mp = n * n / 1e6
        print(f"{n}x{n} PMR {pmr} ({lf.shape}): ours {t_ours * 1e3:.1f} ms/plane ({t_ours / mp * 1e3:.1f} ms/plane/MP), "
              f"baseline {t_base * 1e3:.0f} ms/plane, speed-up {t_base / t_ours:.1f}x, max |diff| {err:.2e}")

    print("== accuracy knobs: depth error of a particle (multiplicative) and time")
    from tests.lightfield.helpers import particle_scene, render

    tmp = Path(tempfile.mkdtemp())
    zs_true = [-15.0, -6.0, 3.0, 11.0]
    raws = []
    for z in zs_true:
        sc = particle_scene(tmp, [[0.4, -0.3, -z]], {"type": "particle_tracer", "rays_per_particle": 100_000}, res=300,
                            mla_pitch_um=50.0)
        raws.append(render(sc))
    cam = sc.sensors()[0].camera
    print(f"depth resolution {cam.depth_resolution():.2f} mm, refocused DOF {cam.depth_of_field()}")
    for interp in ("nearest", "linear", "cubic"):
        for os_ in (1, 2):
            for planes in (51, 201):
                zs = np.linspace(-25, 25, planes)
                t0 = time.perf_counter()
                errs = []
                for raw, z in zip(raws, zs_true, strict=True):
                    lf = lfm.decode(raw, optics=cam, interpolation=interp, angular_oversample=os_)
                    st = lfm.focal_stack(lf, zs, method="multiplicative")
                    errs.append(zs[np.argmax(st.reshape(planes, -1).max(1))] - z)
                dt = (time.perf_counter() - t0) / len(raws)
                print(f"interp {interp:7s} uv x{os_} planes {planes:4d}: {dt * 1e3:7.1f} ms/particle image, "
                      f"|dz| max {np.abs(errs).max():.2f} mm, RMS {np.sqrt(np.mean(np.square(errs))):.2f} mm")

    if args.full:
        print("== 1000-plane focal stack of a 6600x4400 raw image (hex, PMR 14), streamed to disk")
        cam = PlenopticCamera(resolution=(6600, 4400), pixel_pitch_um=5.5, focal_length_mm=50, f_number=2.8,
                              focus_distance_mm=250, mla_pitch_um=77.0, mla_layout="hex")
        t0 = time.perf_counter()
        lf = synthetic_lf(cam)
        print(f"decode {time.perf_counter() - t0:.1f} s, light field {lf.shape}, {lf.data.nbytes / 1e9:.2f} GB")
        out = tmp / "stack.npy"
        t0 = time.perf_counter()
        lfm.focal_stack(lf, np.linspace(-30, 30, 1000), out=out, progress=True)
        dt = time.perf_counter() - t0
        print(f"1000 planes in {dt:.0f} s ({dt:.0f} ms/plane, {dt / 29.04:.1f} ms/plane/MP), file {out.stat().st_size / 1e9:.2f} GB")
        out.unlink()
        del lf
        drop_study_stack(tmp)


def drop_study_stack(tmp):
    """The drop-fragments study's full-size stack (issue 25): the paper's camera
    (paper_003_camera("drop_impact"): 6600x4400 px of 5.5 um, hex lenslets of 77 um, 105 mm
    lens), decoded with the study's 2x spatial supersampling, 1000 planes evenly spaced in
    alpha over the paper's 0.914-1.139, streamed to disk. Synthetic raw (uniform noise): the
    stack's cost does not depend on the content."""
    from mitpiv.analysis.drop_fragments import PAPER_ALPHA_RANGES
    from mitpiv.physics.plenoptic import paper_003_camera
    from mitpiv.replications.drop_fragments.study import SUPERSAMPLE, _stack_depths

    print(f"== drop-fragments study: 1000-plane stack of the paper's 6600x4400 raw, {SUPERSAMPLE}x supersampled")
    cam = paper_003_camera("drop_impact")
    rng = np.random.default_rng(0)
    raw = rng.uniform(0, 1, (cam.resolution[1], cam.resolution[0])).astype(np.float32)
    white = np.ones_like(raw)
    t0 = time.perf_counter()
    lf = lfm.decode(raw, optics=cam, white=white, spatial_oversample=SUPERSAMPLE)
    t_dec = time.perf_counter() - t0
    z = _stack_depths(cam, PAPER_ALPHA_RANGES["drop_impact"], 1000)
    out = tmp / "drop_stack.npy"
    t0 = time.perf_counter()
    lfm.focal_stack(lf, z, out=out, progress=True)
    dt = time.perf_counter() - t0
    print(f"decode {t_dec:.1f} s, light field {lf.shape}; 1000 planes over z {z[0]:+.1f} .. {z[-1]:+.1f} mm in "
          f"{dt:.0f} s ({dt:.0f} ms/plane), file {out.stat().st_size / 1e9:.2f} GB")
    out.unlink()


if __name__ == "__main__":
    main()
