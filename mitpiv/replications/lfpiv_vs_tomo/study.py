"""Replication of Shi et al.'s comparison of single-camera light-field PIV with tomographic PIV
(seed paper 001, section 2 and Tables 1-3): ``mitpiv replicate lfpiv-vs-tomo [--quick]``.

Orchestration only: the cameras, images, reconstructions and metrics are
:mod:`mitpiv.replications.lfpiv_vs_tomo.model` (its docstring lists every reading of what the paper
leaves open), the flow :class:`mitpiv.physics.jet.NearFieldJet`, the paper's axis
:func:`mitpiv.replications.lfpiv_vs_tomo.model.ltpr`. Each case (a light-field camera at one PMR, or
a tomographic rig at one seeding) is one resumable point (``ctx.map``): two frames rendered,
reconstructed and scored.

The experiment replica (section 3, Table 4) is the scene ``scenes/lfpiv_tomo_paper``: its
study's two arms (the light-field camera on a crop of its sensor, the four-camera cross on
the whole volume) run through the experiment runner (``ctx.run``, resumable stages) on the
same simulated jet, and their PIV fields are compared with each other (the paper's
correlation coefficient), with the truth and with section 3's numbers.
"""

from __future__ import annotations

import hashlib
import json
import logging
import math
from pathlib import Path

import numpy as np

from mitpiv.errors import ConfigError
from mitpiv.replications.frame import Curve, Kind, ReplicationResult, Row, Study, compare_trend, compare_value
from mitpiv.replications.lfpiv_vs_tomo.model import MIN_COVERAGE as S_MIN_COVERAGE

log = logging.getLogger(__name__)

PMRS = (7, 14, 28)
CAMERAS = ("low", "high")
NCS = (4, 6, 8)
PPPS = (0.05, 0.1)
#: Table 1: LTPR of each light-field camera against each rig
PAPER_LTPR = {("low", 4): 6.25, ("low", 6): 4.17, ("low", 8): 3.13, ("high", 4): 25.0, ("high", 6): 16.67,
              ("high", 8): 12.5}
#: Table 1: particles in the 12 x 12 x 10 mm volume
PAPER_PARTICLES = {("low", 7): 7524, ("low", 14): 1881, ("low", 28): 470, ("high", 7): 30096, ("high", 14): 7524,
                   ("high", 28): 1881, (0.05,): 1280, (0.1,): 2560}
#: Table 3: reconstruction times normalised by the four-camera Tomo-PIV at 0.05 ppp (TITAN X)
PAPER_TABLE_3 = {("lf", 7, "low"): 55.9811, ("lf", 14, "low"): 3.7750, ("lf", 28, "low"): 7.2170,
                 ("lf", 7, "high"): 1269.4, ("lf", 14, "high"): 15.2940, ("lf", 28, "high"): 55.2826,
                 ("tomo", 4, 0.05): 1.0, ("tomo", 4, 0.1): 1.0093, ("tomo", 6, 0.05): 1.1405,
                 ("tomo", 6, 0.1): 1.1550, ("tomo", 8, 0.05): 1.3690, ("tomo", 8, 0.1): 1.3744}
#: the headline crossing (section 2.3): LF-PIV at PMR 14 equals or beats N_c-camera Tomo-PIV from this LTPR
PAPER_CROSSING = {4: 25.0, 6: 16.67, 8: 12.5}
#: Fig. 8a's one number: the w error of LF-PIV at PMR 14, high LTPR [px]
PAPER_W_RMS_PMR14_HIGH = 0.15
#: order-of-magnitude tolerance of the time ratios (other hardware, other code)
TIME_FACTOR = 3.0


def scale(quick: bool) -> dict:
    """The crops and settings of each scale (same code, same row ids)."""
    if quick:
        return {"lf_crop_mm": {"low": 1.2, "high": 0.6}, "lf_iterations": 5, "drt_rays_per_pixel": 4,
                "rays_per_aperture_pixel": 4.0, "window_scale": 1.0, "tomo_crop_y_mm": 0.3, "tomo_iterations": 5,
                "convergence_random_rays": 400_000, "convergence_levels": (1.0, 4.0, 16.0),
                "depth_crop_mm": (1.2, 2.4), "depth_iterations": (3, 10)}
    # light field: a strip across the whole shear layer (y: the first pass needs several windows
    # across the mean shear to give the second a deforming predictor; measured on ideal volumes,
    # LF low PMR 14: u error 2.7 -> 0.8 voxels from a 4.8 mm square to a 4.8 x 12 mm strip), cropped
    # along the jet axis x, where the flow varies slowly
    return {"lf_crop_mm": {"low": (4.8, 12.0), "high": (2.4, 7.2)}, "lf_iterations": 400, "drt_rays_per_pixel": 8,
            "rays_per_aperture_pixel": 256.0, "window_scale": 1.0, "tomo_crop_y_mm": 12.0, "tomo_iterations": 40,
            "convergence_random_rays": 5_000_000, "convergence_levels": (1.0, 4.0, 16.0, 64.0, 256.0, 1024.0),
            # the errors by depth: LF low PMR 14 on half the strip (4.8 x 6 mm) at 20 / 100 / 400 iterations
            "depth_crop_mm": (4.8, 6.0), "depth_iterations": (20, 100, 400)}


def _crop(c) -> tuple[float, float]:
    """A light-field crop: one length (a central square) or (x, y) [mm]."""
    return (float(c), float(c)) if np.isscalar(c) else (float(c[0]), float(c[1]))


def _items(sc: dict, seed: int) -> list[dict]:
    out = []
    for cam in CAMERAS:
        for pmr in PMRS:
            cx, cy = _crop(sc["lf_crop_mm"][cam])
            out.append({"kind": "lf", "camera": cam, "pmr": pmr, "crop_mm": cx, "crop_y_mm": cy,
                        "iterations": sc["lf_iterations"], "drt": sc["drt_rays_per_pixel"], "cov": S_MIN_COVERAGE,
                        "rays": sc["rays_per_aperture_pixel"], "ws": sc["window_scale"], "seed": seed})
    for nc in NCS:
        for ppp in PPPS:
            out.append({"kind": "tomo", "nc": nc, "ppp": ppp, "crop_y_mm": sc["tomo_crop_y_mm"],
                        "iterations": sc["tomo_iterations"], "ws": sc["window_scale"], "seed": seed})
    return out


def _key(it: dict) -> str:
    if it["kind"] == "lf":
        return (f"lf_{it['camera']}_pmr{it['pmr']}_c{it['crop_mm']:g}x{it['crop_y_mm']:g}_it{it['iterations']}"
                f"_drt{it['drt']}_cov{it['cov']:g}"
                f"_r{it['rays']:g}_ws{it['ws']:g}_s{it['seed']}")
    return f"tomo_nc{it['nc']}_ppp{it['ppp']:g}_c{it['crop_y_mm']:g}_it{it['iterations']}_ws{it['ws']:g}_s{it['seed']}"


def case_point(it: dict) -> dict:
    """One case (a Dask task): two frames rendered, reconstructed, scored."""
    from mitpiv.replications.lfpiv_vs_tomo import model as S

    if it["kind"] == "lf":
        return S.lf_point(S.LFCase(it["camera"], it["pmr"], it["crop_mm"], it["crop_y_mm"]), iterations=it["iterations"],
                          rays_per_aperture_pixel=it["rays"], drt_rays_per_pixel=it["drt"], window_scale=it["ws"],
                          min_coverage=it["cov"],
                          seed=1000 * it["seed"] + 7 * it["pmr"] + (1 if it["camera"] == "high" else 0))
    return S.tomo_point(S.TomoCase(it["nc"], it["ppp"], it["crop_y_mm"]), iterations=it["iterations"],
                        window_scale=it["ws"], seed=1000 * it["seed"] + 11 * it["nc"] + int(100 * it["ppp"]))


#: measured single-core rates (this session, 2-core machine under a load of ~8, nice): DRT
#: weights per traced ray-slab sample (34 s for 1.1e8 samples: LF low PMR 14, 4.8 mm square),
#: DRT-MART per active weight entry and iteration (33 s for 50 x 2.7e7), SMART per voxel, camera
#: and iteration (28 s per frame: 4 cameras, 1.36e6 voxels, 40 iterations), PIV + truth per
#: vector and window voxel (19 s for 3.7e7 and 13 s for 6.2e7)
SECONDS_PER_DRT_SAMPLE = 3.1e-7
SECONDS_PER_DRT_UPDATE = 2.5e-8
SECONDS_PER_SMART_VOXEL_CAMERA_ITER = 1.3e-7
SECONDS_PER_WINDOW_VOXEL = 4e-7
#: active DRT entries per sensor pixel and slab (measured: 3.9 at 8 rays per pixel, 2 substeps, PMR 14 low)
DRT_ACTIVE_PER_PIXEL_SLAB = 3.9


def cost_estimate(quick: bool) -> dict:
    """Estimated single-core seconds of a scale from the measured rates (light-field cases,
    tomographic cases; each with its PIV on the reconstructions and on the ideal volumes)."""
    from mitpiv.replications.lfpiv_vs_tomo import model as S

    sc = scale(quick)
    lf_s, tomo_s = 0.0, 0.0
    for cam in CAMERAS:
        for pmr in PMRS:
            c = S.LFCase(cam, pmr, *_crop(sc["lf_crop_mm"][cam]))
            nz = c.grid().shape[0]
            px = c.pixels
            weights = px * sc["drt_rays_per_pixel"] * 2 * nz * SECONDS_PER_DRT_SAMPLE
            mart = 2 * px * nz * DRT_ACTIVE_PER_PIXEL_SLAB * sc["lf_iterations"] * SECONDS_PER_DRT_UPDATE
            passes = S.window_plan("lf", pmr, fit_shape_zyx=c.grid().shape, scale=sc["window_scale"])
            lf_s += weights + mart + 2 * _window_voxels(c.grid().shape, passes) * SECONDS_PER_WINDOW_VOXEL
    for nc in NCS:
        for ppp in PPPS:
            c = S.TomoCase(nc, ppp, sc["tomo_crop_y_mm"])
            vox = int(np.prod(c.grid().shape))
            passes = S.window_plan("tomo", ppp, fit_shape_zyx=c.grid().shape, scale=sc["window_scale"])
            tomo_s += 2 * vox * nc * sc["tomo_iterations"] * SECONDS_PER_SMART_VOXEL_CAMERA_ITER \
                + 2 * _window_voxels(c.grid().shape, passes) * SECONDS_PER_WINDOW_VOXEL
    exp_s = _experiment_cost_s(quick)
    return {"points": len(CAMERAS) * len(PMRS) + len(NCS) * len(PPPS), "lf_s": lf_s, "tomo_s": tomo_s,
            "experiment_s": exp_s, "cpu_s": lf_s + tomo_s + exp_s}


def _experiment_cost_s(quick: bool) -> float:
    """The replica's two arms, run twice (as Table 4 and :func:`variant_arms`), two frames each:
    DRT-MART (:func:`mitpiv.costs.drt_mart_cost`, one entry per pixel, ray and slab, the weights
    built for the first frame only), MLOS-SMART over the four cameras and the PIV of every pass
    (:func:`mitpiv.costs.piv_cost`); not the rendering."""
    from mitpiv import costs
    from mitpiv.studies.runner import load_experiment

    arms = experiment_arms(quick)
    total, lf_slabs = 0.0, 0
    for variant in (arms, variant_arms(arms)):
        for arm, ov in variant.items():
            cfg = load_experiment(experiment_dir() / "experiment.toml", ov)
            r = cfg.reconstruction
            vox = np.broadcast_to(np.asarray(r.voxel_mm, dtype=float), (3,))
            b = np.asarray(r.bounds_mm, dtype=float).reshape(3, 2)
            n_xyz = [int(math.ceil(round((hi - lo) / v, 6))) for (lo, hi), v in zip(b, vox, strict=True)]
            n = float(np.prod(n_xyz))
            if arm == "lf":
                p = cfg.scene.params
                c = costs.drt_mart_cost(p["lf_width"] * p["lf_height"], r.rays_per_pixel, n_xyz[2],
                                        iterations=r.iterations, n_voxels=n)
                lf_slabs = n_xyz[2]
                total -= p["lf_width"] * p["lf_height"] * r.rays_per_pixel * n_xyz[2] / costs.DRT_ENTRIES_PER_S
            else:
                c = costs.reconstruction_cost(n, n_images=len(cfg.render.sensors), iterations=r.iterations,
                                              method=r.method)
            total += 2 * c.seconds + costs.piv_cost(n_xyz[::-1], cfg.piv.windows, cfg.piv.overlap).seconds
    # the ideal-volume factor study (experiment_ideal): 4 seedings x flows, 2 and 4 passes each
    f = IDEAL_FACTORS_QUICK if quick else IDEAL_FACTORS_FULL
    shape = (lf_slabs, f["crop_px"][1] // 2, f["crop_px"][0] // 2)  # 2 px per lateral voxel
    for wins in ([f["first"], f["final"]], [f["first"]] + [f["final"]] * 3):
        total += 4 * costs.piv_cost(shape, wins, 0.75).seconds
    return total


def _vectors_per_axis(n_xyz, w_xyz) -> tuple[int, ...]:
    """Vectors per axis of windows ``w_xyz`` at 75 % overlap over a grid of ``n_xyz`` voxels."""
    return tuple(max(1, int((n - w) // max(1, int(round(0.25 * w))) + 1)) for n, w in zip(n_xyz, w_xyz, strict=True))


def _window_voxels(shape_zyx, passes) -> float:
    """Sum over the passes of vectors x window voxels (75 % overlap)."""
    return sum(float(np.prod(_vectors_per_axis(shape_zyx[::-1], w))) * float(np.prod(w)) for w in passes)


def convergence(sc: dict, seed: int) -> dict:
    """Relative L2 difference between the stratified images of one particle (PMR 14, low LTPR
    camera, 2 mm behind the focal plane) at increasing ray densities and a Monte Carlo image of
    ``convergence_random_rays`` random rays (the paper's model; 5 million in the full run)."""
    from mitpiv.replications.lfpiv_vs_tomo import model as S

    cam = S.lf_camera(S.LFCase("low", 14, 2.4))
    p = np.array([[0.05, -0.03, 2.0]])
    ref = S.render_light_field(cam, p, rays_per_aperture_pixel=1, seed=seed + 1,
                               random_rays=sc["convergence_random_rays"])
    ref = ref / ref.sum()
    # the Monte Carlo reference's own noise: a second, independent random image
    ref2 = S.render_light_field(cam, p, rays_per_aperture_pixel=1, seed=seed + 2,
                                random_rays=sc["convergence_random_rays"])
    ref2 = ref2 / ref2.sum()
    noise = float(np.linalg.norm(ref2 - ref) / np.linalg.norm(ref) / math.sqrt(2.0))
    out = {"levels": [], "rays": [], "rel_l2": [], "reference_noise": noise,
           "random_rays": sc["convergence_random_rays"]}
    for lv in sc["convergence_levels"]:
        im = S.render_light_field(cam, p, rays_per_aperture_pixel=lv, seed=seed + 3)
        im = im / im.sum()
        out["levels"].append(lv)
        out["rays"].append(S.rays_per_particle(cam, lv))
        out["rel_l2"].append(float(np.linalg.norm(im - ref) / np.linalg.norm(ref)))
    return out


# ---------------------------------------------------------------------- experiment replica
#: section 3 / Table 4: spurious vectors, vector counts, the LF-Tomo correlation, the times
PAPER_EXP = {"lf_outlier_pct": 4.1, "tomo_outlier_pct": 5.2, "lf_vectors": (79, 51, 19), "tomo_vectors": (57, 37, 13),
             "correlation": 0.94, "lf_reconstruct_s": 4.5 * 3600.0, "tomo_reconstruct_s": 10.7, "ltpr": 47.27}
#: the paper's full light-field grid (3300 x 2200 x 182 voxels) and sensor
PAPER_EXP_LF_GRID = (3300, 2200, 182)
PAPER_EXP_LF_SENSOR = (6600, 4400)
EXPERIMENT_SCENE = "lfpiv_tomo_paper"


def experiment_dir() -> Path:
    """``scenes/lfpiv_tomo_paper`` of the source tree (the replica scene)."""
    d = Path(__file__).resolve().parents[3] / "scenes" / EXPERIMENT_SCENE
    if not (d / "study.toml").is_file():
        raise ConfigError(f"lfpiv-vs-tomo: the experiment replica scene is not at {d}; run the replication from a "
                          "checkout of the mitpiv repository (the scenes folder is not installed with the package).")
    return d


def experiment_arms(quick: bool, seed: int = 0) -> dict[str, dict]:
    """The overrides of each arm (``"lf"``, ``"tomo"``) of ``scenes/lfpiv_tomo_paper``'s
    experiment: its study's two points, with the replication's ``seed``; the quick scale shrinks both (a 220 x 220 px
    light-field crop, a 6 x 6 x 10 mm tomographic box, 3 iterations) on the same lip line."""
    from mitpiv.studies.sweep import load_study

    st = load_study(experiment_dir() / "study.toml")
    arms = {}
    for p in st["points"]:
        arm = "tomo" if p.get("reconstruction.method") == "smart" else "lf"
        arms[arm] = {k: v for k, v in p.items() if k != "label"}
    for a in arms.values():
        a["seed"] = int(seed)
    if set(arms) != {"lf", "tomo"}:
        raise ConfigError(f"lfpiv-vs-tomo: {EXPERIMENT_SCENE}/study.toml must hold one light-field and one SMART "
                          f"point; found {sorted(arms)}.")
    if quick:
        arms["lf"].update({"scene.params.lf_width": 220, "scene.params.lf_height": 220,
                           "scene.params.rays_per_particle": 20000,
                           "seeding.box_min_mm": [-1.638, 8.362, -5.0], "seeding.box_max_mm": [1.638, 11.638, 5.0],
                           "reconstruction.bounds_mm": [-0.638, 0.638, 9.362, 10.638, -5.0, 5.0],
                           "reconstruction.iterations": 3, "piv.windows": [[64, 64, 32], [48, 48, 16]]})
        arms["tomo"].update({"seeding.box_min_mm": [-4.0, 6.0, -5.0], "seeding.box_max_mm": [4.0, 14.0, 5.0],
                             "reconstruction.bounds_mm": [-3.0, 3.0, 7.0, 13.0, -5.135, 5.135],
                             "reconstruction.iterations": 3, "piv.windows": [32, 16]})
    return arms


def _arm_key(arms: dict) -> str:
    """The arms' overrides and the scene's files (experiment, study, scene XML): a changed
    scene is a new cache key."""
    d = experiment_dir()
    files = "".join((d / f).read_text() for f in ("experiment.toml", "study.toml", "scene.xml"))
    return hashlib.sha1((json.dumps(arms, sort_keys=True) + files).encode()).hexdigest()[:10]


def _common_points_correlation(a: dict, b: dict) -> dict:
    """Vector correlation of two PIV fields where they overlap: ``b`` interpolated
    (trilinear) at ``a``'s valid vectors inside ``b``'s grid; ``r = sum (a - <a>).(b - <b>) /
    sqrt(sum |a - <a>|^2 sum |b - <b>|^2)`` over the 3 components (the mean vector removed, so
    the shared mean flow does not count), and the RMS difference [mm/s]."""
    from scipy.interpolate import RegularGridInterpolator

    za, ya, xa = np.meshgrid(a["z_mm"], a["y_mm"], a["x_mm"], indexing="ij")
    pa = np.stack([za, ya, xa], -1).reshape(-1, 3)
    va = np.stack([a["u"], a["v"], a["w"]], -1).reshape(-1, 3)
    lo = [float(np.min(b[k])) for k in ("z_mm", "y_mm", "x_mm")]
    hi = [float(np.max(b[k])) for k in ("z_mm", "y_mm", "x_mm")]
    ok = np.asarray(a["valid"]).reshape(-1) & np.all((pa >= lo) & (pa <= hi), axis=1)  # a new array: a is not touched
    if ok.sum() < 2:
        return {"n": int(ok.sum()), "r": math.nan, "rms_diff_mm_s": math.nan}
    vb = np.stack([RegularGridInterpolator((b["z_mm"], b["y_mm"], b["x_mm"]), b[c])(pa[ok]) for c in "uvw"], -1)
    va = va[ok]
    fin = np.all(np.isfinite(vb), axis=1) & np.all(np.isfinite(va), axis=1)  # a missing vector of either field
    va, vb = va[fin], vb[fin]
    if len(va) < 2:
        return {"n": int(len(va)), "r": math.nan, "rms_diff_mm_s": math.nan}
    da, db = va - va.mean(0), vb - vb.mean(0)
    r = float(np.sum(da * db) / math.sqrt(np.sum(da**2) * np.sum(db**2)))
    keep = np.random.default_rng(0).permutation(len(va))[:2000]  # a sample for the figure
    return {"n": int(len(va)), "r": r, "rms_diff_mm_s": float(np.sqrt(np.mean(np.sum((va - vb) ** 2, 1)))),
            "sample_a": np.round(va[keep], 3).tolist(), "sample_b": np.round(vb[keep], 3).tolist()}


def _arm_run(ctx, arm: str, overrides: dict, key: str, variant: str = ""):
    """The replica arm's resumable experiment run ``work/runs/experiment_<arm>[_<variant>]_<key>``
    (a finished run is read back, nothing recomputed). The quick scale stops after the PIV:
    the replication reads the run's fields and metrics, not its report (a quarter of a quick
    arm's time went into the report's figures); its metrics are then the kind's summary of the
    stages that ran, as a whole run writes them."""
    import dataclasses

    from mitpiv.studies.kinds import get_kind
    from mitpiv.studies.runner import load_experiment

    cfg = load_experiment(experiment_dir() / "experiment.toml", overrides)
    res = ctx.run(f"experiment_{arm}_{variant + '_' if variant else ''}{key}", cfg,
                  until="piv" if ctx.quick else None)
    if not res.metrics:
        res = dataclasses.replace(res, metrics=get_kind(cfg.kind).summary(cfg, res.stages))
    return res


def variant_arms(arms: dict) -> dict[str, dict]:
    """The replica's arms with the jet's mean flow only (``flow.envelope = 0``: no synthetic
    turbulence) and two more PIV passes at each arm's final window: the settings under which
    the ideal volumes of :func:`experiment_ideal` measure the paper's spurious-vector rate, run
    through the whole chain (render, reconstruction, PIV)."""
    from mitpiv.studies.runner import load_experiment

    out = {}
    for arm, ov in arms.items():
        w = ov.get("piv.windows")
        if w is None:  # the experiment's own windows
            w = load_experiment(experiment_dir() / "experiment.toml", ov).piv.windows
        w = [list(x) if not np.isscalar(x) else x for x in w]
        out[arm] = {**ov, "flow.envelope": 0.0, "piv.windows": w + [w[-1], w[-1]]}
    return out


def experiment_summary(ctx, quick: bool, variant: str = "") -> dict:
    """Run both arms of the replica (resumable experiment runs under ``work/runs``) and
    reduce them to section 3's numbers; ``variant="mean4"``: :func:`variant_arms`."""
    from mitpiv.io.vectors import read_vector_field

    arms = experiment_arms(quick, ctx.seed)
    key = _arm_key(arms)
    if variant == "mean4":
        arms = variant_arms(arms)
    elif variant:
        raise ConfigError(f"lfpiv-vs-tomo: experiment variant {variant!r} is not known; use '' or 'mean4'.")
    out = {"arms": arms, "key": key, "variant": variant}
    fields = {}
    for arm, ov in arms.items():
        res = _arm_run(ctx, arm, ov, key, variant)
        m = res.metrics
        piv = m.get("piv") or {}
        fld = read_vector_field(res.run_dir / "piv" / "field.npz")
        fields[arm] = fld
        cams = m.get("cameras") or {}
        out[arm] = {"rms_vox": piv.get("rms_vox"), "rms_mm_s": piv.get("rms"), "outlier_ratio": piv.get("outlier_ratio"),
                    "n_vectors": int(np.prod(fld["u"].shape)), "vectors_zyx": list(fld["u"].shape),
                    "reconstruct_s": float(res.timings.get("reconstruct", math.nan)),
                    "render_s": float(res.timings.get("render", math.nan)), "timings": res.timings,
                    "cameras": cams, "Q": (m.get("evaluate") or {}).get("frame0", {}).get("Q"),
                    "particles": (m.get("evaluate") or {}).get("frame0", {}).get("particles")}
    out["lf_vs_tomo"] = _common_points_correlation(fields["lf"], fields["tomo"])
    return out


#: the ideal-volume factor study of the replica's light-field arm: a synthetic crop twice the
#: run's each way (so Table 4's 320 x 320 x 64 first window fits), the seeding x1 and x4, the
#: jet with and without its turbulence, the paper's two passes and two more at the final size
IDEAL_FACTORS_FULL = {"crop_px": (1320, 880), "first": [320, 320, 64], "final": [160, 160, 32]}
IDEAL_FACTORS_QUICK = {"crop_px": (220, 220), "first": [96, 96, 64], "final": [64, 64, 32]}
IDEAL_SEEDING_FACTORS = (1.0, 4.0)
IDEAL_SIGMA_VOXELS = 1.0


def _ideal_piv(p0, p1, grid, flow, dt_s: float, piv: dict) -> dict:
    """The runner's PIV (same settings) on ideal volumes (Gaussian blobs of
    ``IDEAL_SIGMA_VOXELS`` at ``p0`` and ``p1``), scored as the runner scores it
    (:func:`velocity_error` against the flow averaged over each window, replaced outliers
    included): RMS [voxels], outlier ratio, median |error| [voxels] of the vectors kept."""
    from mitpiv.analysis.piv3d import piv3d, velocity_error
    from mitpiv.analysis.quality import truth_volume

    kw = {k: piv[k] for k in ("overlap", "deform", "interpolation", "normalised", "correlation", "threshold",
                              "replace") if k in piv}
    if kw.get("replace") == "none":  # the schema's word for no replacement
        kw["replace"] = None
    fld = piv3d(truth_volume(p0, grid, IDEAL_SIGMA_VOXELS), truth_volume(p1, grid, IDEAL_SIGMA_VOXELS), grid,
                windows=[list(w) if not np.isscalar(w) else w for w in piv["windows"]], dt_s=dt_s, **kw)
    ve = velocity_error(fld, flow)
    err = np.asarray(ve["error"]).reshape(-1, 3) * dt_s / np.asarray(grid.voxel_mm)
    keep = np.all(np.isfinite(err), axis=1) & ~np.asarray(fld.outlier).reshape(-1)
    med = np.median(np.abs(err[keep]), axis=0).tolist() if keep.any() else [math.nan] * 3
    return {"rms_vox": [float(v) for v in ve["rms_vox"]], "outlier_ratio": float(fld.outlier_ratio),
            "median_abs_vox": med, "n_vectors": int(fld.n_vectors), "vectors_zyx": list(fld.u.shape)}


def subwindow_motion(flow, centres_mm, window_mm, voxel_mm, dt_s: float, *, samples: int = 256, seed: int = 0) -> dict:
    """How much the flow moves particles apart inside interrogation windows, in voxels: the
    displacement ``u dt`` at ``samples`` random points of each window (centred on
    ``centres_mm``), its spread (standard deviation about the window's mean) and what is left
    after a least-squares linear fit (the part a deforming window cannot follow), RMS over the
    windows per component [voxels], to set beside the particle images' size (a few voxels)."""
    rng = np.random.default_rng(seed)
    c = np.asarray(centres_mm, dtype=float).reshape(-1, 3)
    off = (rng.random((int(samples), 3)) - 0.5) * np.asarray(window_mm, dtype=float)
    d = flow.velocity((c[:, None, :] + off[None]).reshape(-1, 3), 0.0).reshape(len(c), len(off), 3) * dt_s
    d = d / np.asarray(voxel_mm, dtype=float)
    spread = d - d.mean(axis=1, keepdims=True)
    x = np.column_stack([np.ones(len(off)), off])  # (S, 4): a + B (x - c)
    res = d - np.einsum("sk,wkc->wsc", x, np.einsum("ks,wsc->wkc", np.linalg.pinv(x), d))
    return {"spread_vox": np.sqrt(np.mean(spread**2, axis=(0, 1))).tolist(),
            "nonlinear_vox": np.sqrt(np.mean(res**2, axis=(0, 1))).tolist(), "windows": len(c),
            "window_mm": [float(v) for v in np.broadcast_to(np.asarray(window_mm, dtype=float), (3,))]}


def experiment_subwindow(ctx, arms: dict, n_windows: int = 400) -> dict:
    """:func:`subwindow_motion` of each arm of the replica: its flow and pulse separation, its
    final window and voxel, ``n_windows`` window centres at random in the light-field arm's
    grid (the region both arms measure), the jet with and without its turbulence."""
    from mitpiv.io.records import read_json
    from mitpiv.physics.flows import flow_from_dict

    key = _arm_key(arms)
    exps = {arm: read_json(_arm_run(ctx, arm, arms[arm], key).run_dir / "experiment.json") for arm in ("lf", "tomo")}
    b = np.asarray(exps["lf"]["reconstruction"]["bounds_mm"], dtype=float).reshape(3, 2)
    rng = np.random.default_rng(1000 * ctx.seed + 11)
    centres = b[:, 0] + rng.random((int(n_windows), 3)) * (b[:, 1] - b[:, 0])
    out = {}
    for arm, exp in exps.items():
        fd = dict(exp["flow"])
        dt = float(fd.pop("dt_s"))
        vox = np.broadcast_to(np.asarray(exp["reconstruction"]["voxel_mm"], dtype=float), (3,))
        win = np.broadcast_to(np.asarray(exp["piv"]["windows"][-1], dtype=float), (3,)) * vox
        out[arm] = {f"envelope{env:g}": subwindow_motion(flow_from_dict({**fd, "envelope": env}), centres, win, vox, dt,
                                                         seed=1000 * ctx.seed + 12)
                    for env in (1.0, 0.0)}
    return out


def _same_particles(ctx, arms: dict, run_key: str, variant: str = "") -> dict:
    """Each arm's own truth particles (its run in ``work/runs``) as ideal volumes on the arm's
    grid, the arm's PIV settings: the error without the reconstruction's. Also the run's
    experiment, grid and flow (for :func:`experiment_ideal`'s factors)."""
    from mitpiv.io.particles import read_truth
    from mitpiv.io.records import read_json
    from mitpiv.io.volume import read_volume
    from mitpiv.physics.flows import flow_from_dict

    out = {}
    for arm in ("lf", "tomo"):
        d = _arm_run(ctx, arm, arms[arm], run_key, variant).run_dir
        exp = read_json(d / "experiment.json")
        _, grid, _ = read_volume(d / "reconstruct" / "volume_0.npz")
        fd = dict(exp["flow"])
        dt = float(fd.pop("dt_s"))
        pos = read_truth(d / "particles" / "truth.npz")["positions_mm"]
        r = _ideal_piv(pos[0], pos[1], grid, flow_from_dict(fd), dt, exp["piv"])
        w = np.asarray(exp["piv"]["windows"][-1], dtype=float) * np.ones(3)
        r.update({"particles_per_final_window": float(exp["seeding"]["concentration_per_mm3"]
                                                      * np.prod(w * np.asarray(grid.voxel_mm))),
                  "grid_zyx": list(grid.shape), "final_window": w.astype(int).tolist(),
                  "windows": exp["piv"]["windows"]})
        out[arm] = (r, exp, grid, fd, dt)
    return out


def experiment_ideal(ctx, arms: dict, quick: bool) -> dict:
    """Why the replica's light-field PIV fails: its PIV on ideal volumes.

    * ``same``: :func:`_same_particles` of the replica's runs.
    * ``factors``: the light-field arm's voxel, flow and pulse separation on a synthetic crop
      twice the run's each way (:data:`IDEAL_FACTORS_FULL`, Table 4's windows fit), seeded at
      the replica's concentration times each of :data:`IDEAL_SEEDING_FACTORS`, the jet with and
      without its turbulence (``envelope`` 1 and 0), with the paper's two passes and with two
      more at the final window.
    """
    from mitpiv.grid import VoxelGrid
    from mitpiv.physics.advection import advect
    from mitpiv.physics.flows import flow_from_dict

    same = _same_particles(ctx, arms, _arm_key(arms))
    out: dict = {"same": {arm: v[0] for arm, v in same.items()}, "sigma_voxels": IDEAL_SIGMA_VOXELS}
    _, lf_exp, lf_grid, lf_flow, lf_dt = same["lf"]
    f = IDEAL_FACTORS_QUICK if quick else IDEAL_FACTORS_FULL
    vox = np.asarray(lf_grid.voxel_mm)
    b = np.asarray(lf_exp["reconstruction"]["bounds_mm"], dtype=float).reshape(3, 2)
    xc, yc = float(b[0].mean()), float(b[1].mean())
    half = np.array([f["crop_px"][0] * vox[0], f["crop_px"][1] * vox[1]]) / 4  # 2 px per voxel laterally (2:2:10)
    lo, hi = np.array([xc - half[0], yc - half[1], b[2, 0]]), np.array([xc + half[0], yc + half[1], b[2, 1]])
    grid = VoxelGrid.from_bounds(lo, hi, vox)
    blo, bhi = lo - [1.0, 1.0, 0.0], hi + [1.0, 1.0, 0.0]  # seeded 1 mm beyond the crop, as the replica
    conc = float(lf_exp["seeding"]["concentration_per_mm3"])
    out.update({"crop_px": list(f["crop_px"]), "grid_zyx": list(grid.shape), "concentration_per_mm3": conc,
                "factors": []})
    passes = {2: [f["first"], f["final"]], 4: [f["first"], f["final"], f["final"], f["final"]]}
    for s in IDEAL_SEEDING_FACTORS:
        rng = np.random.default_rng(1000 * ctx.seed + 7)
        n = int(rng.poisson(s * conc * np.prod(bhi - blo)))
        p0 = blo + rng.random((n, 3)) * (bhi - blo)
        for env in (1.0, 0.0):
            flow = flow_from_dict({**lf_flow, "envelope": env})
            p1 = advect(p0, flow.velocity, dt_s=lf_dt, substeps=4)
            for npass, wins in passes.items():
                r = _ideal_piv(p0, p1, grid, flow, lf_dt, {**lf_exp["piv"], "windows": wins})
                r.update({"seeding_factor": s, "envelope": env, "passes": npass, "windows": wins, "particles": n,
                          "particles_per_final_window": s * conc * float(np.prod(np.asarray(f["final"]) * vox))})
                log.info("lfpiv-vs-tomo: ideal replica crop, seeding x%g, envelope %g, %d passes: RMS %s voxels, "
                         "%.1f %% outliers", s, env, npass, _v3(r["rms_vox"]), 100 * r["outlier_ratio"])
                out["factors"].append(r)
    return out


def _ideal_label(r: dict) -> str:
    return (f"seeding x{r['seeding_factor']:g}, {'turbulent jet' if r['envelope'] else 'mean flow only'}, "
            f"{r['passes']} passes")


def _ideal_rows(E: dict, I: dict) -> list[Row]:
    rows = []
    for arm, name in (("lf", "LF-PIV"), ("tomo", "Tomo-PIV")):
        r = I["same"][arm]
        rows.append(Row(f"experiment_{arm}_ideal_rms_vox", f"{name} RMS error on ideal volumes of the replica's own "
                        "particles (same grid, windows and scoring; the reconstruction left out)", "diagnostic",
                        "not in the paper", _num(_rms3(r["rms_vox"])), unit="voxel",
                        note=f"u / v / w {_v3(r['rms_vox'])}, {100 * r['outlier_ratio']:.1f} % outliers; on the "
                        f"reconstructions {_v3(E[arm]['rms_vox'] or [math.nan] * 3)}, "
                        f"{100 * E[arm]['outlier_ratio']:.1f} %"))
        rows.append(Row(f"experiment_{arm}_particles_per_final_window", f"{name} particles per final window in the "
                        "replica (concentration x window volume)", "Sect. 2 (the rule: 7 ~ 10 per final window)",
                        "7 ~ 10 (the paper's rule for its simulations)", _num(r["particles_per_final_window"]),
                        note=f"final window {' x '.join(map(str, r['final_window']))} voxels"))
    for r in I["factors"]:
        rid = (f"experiment_ideal_seeding_x{r['seeding_factor']:g}_{'turbulent' if r['envelope'] else 'mean'}"
               f"_{r['passes']}pass")
        rows.append(Row(rid, f"LF-PIV on ideal volumes of a {I['crop_px'][0]} x {I['crop_px'][1]} px crop of the "
                        f"replica: {_ideal_label(r)}", "diagnostic", "not in the paper", _num(_rms3(r["rms_vox"])),
                        unit="voxel", note=f"u / v / w {_v3(r['rms_vox'])}, median |error| {_v3(r['median_abs_vox'])}, "
                        f"{100 * r['outlier_ratio']:.1f} % outliers, {r['particles_per_final_window']:.1f} particles "
                        "per final window"))
    return rows


def _variant_rows(V: dict, VI: dict) -> list[Row]:
    rows = []
    for arm, name in (("lf", "LF-PIV"), ("tomo", "Tomo-PIV")):
        v = V[arm]
        rows.append(Row(f"experiment_mean4_{arm}_outlier_pct", f"{name} spurious vectors in the replica with the jet's "
                        "mean flow only and two more passes at the final window (the whole chain)", "diagnostic",
                        f"{PAPER_EXP[arm + '_outlier_pct']:g} % (the paper's measured jet, Table 4's two passes)",
                        _num(100.0 * float(v["outlier_ratio"])), unit="%",
                        note=f"RMS error u / v / w {_v3(v['rms_vox'] or [math.nan] * 3)} voxels, {v['n_vectors']} "
                        f"vectors; ideal volumes of the same particles and settings {100 * VI[arm]['outlier_ratio']:.1f} "
                        f"%, {_v3(VI[arm]['rms_vox'])} voxels"))
    c = V["lf_vs_tomo"]
    rows.append(Row("experiment_mean4_lf_tomo_correlation", "LF-PIV vs Tomo-PIV correlation where they overlap, the "
                    "jet's mean flow only, two more passes at the final window", "diagnostic",
                    f"{PAPER_EXP['correlation']:g} (the paper's measured jet)", _num(c["r"]),
                    note=f"{c['n']} light-field vectors; RMS difference {c['rms_diff_mm_s']:.2f} mm/s"))
    return rows


def _variant_section(V: dict, VI: dict) -> str:
    """The whole chain with the jet's mean flow and two more passes, beside its ideal volumes."""
    lf, tomo, c = V["lf"], V["tomo"], V["lf_vs_tomo"]
    if lf["outlier_ratio"] <= 2 * PAPER_EXP["lf_outlier_pct"] / 100:
        verdict = (f"the light-field chain then keeps the paper's kind of result ({100 * lf['outlier_ratio']:.1f} % "
                   f"against the paper's {PAPER_EXP['lf_outlier_pct']:g} %)")
    elif VI["lf"]["outlier_ratio"] <= 2 * PAPER_EXP["lf_outlier_pct"] / 100:
        verdict = (f"the light-field reconstruction fails on its own here: {100 * lf['outlier_ratio']:.1f} % outliers "
                   f"against {100 * VI['lf']['outlier_ratio']:.1f} % on ideal volumes of the same particles and "
                   "settings")
    else:
        verdict = (f"the PIV fails on ideal volumes of the same particles and settings too "
                   f"({100 * VI['lf']['outlier_ratio']:.1f} %; reconstructed {100 * lf['outlier_ratio']:.1f} %)")
    return (
        "### The whole chain with the jet's mean flow and four passes\n\n"
        "Both arms rendered, reconstructed and correlated again with the jet's mean flow only (`flow.envelope = "
        "0`) and two more passes at each arm's final window (`variant_arms`): LF-PIV "
        f"{100 * lf['outlier_ratio']:.1f} % spurious vectors, RMS error u / v / w "
        f"{_v3(lf['rms_vox'] or [math.nan] * 3)} voxels (ideal volumes of the same particles and settings "
        f"{100 * VI['lf']['outlier_ratio']:.1f} %, {_v3(VI['lf']['rms_vox'])}); Tomo-PIV "
        f"{100 * tomo['outlier_ratio']:.1f} %, {_v3(tomo['rms_vox'] or [math.nan] * 3)} voxels (ideal "
        f"{100 * VI['tomo']['outlier_ratio']:.1f} %, {_v3(VI['tomo']['rms_vox'])}); LF vs Tomo r = {c['r']:.3f} over "
        f"{c['n']} vectors (the mean vector removed; the paper 0.94). So {verdict}.")


def _ideal_section(E: dict, I: dict, M: dict) -> str:
    s, f = I["same"], I["factors"]

    def pick(seed, env, npass):
        return next(r for r in f if r["seeding_factor"] == seed and r["envelope"] == env and r["passes"] == npass)

    def pct(r):
        return f"{100 * r['outlier_ratio']:.0f} %"

    base, dense, mean, more = pick(1.0, 1.0, 2), pick(4.0, 1.0, 2), pick(1.0, 0.0, 2), pick(1.0, 1.0, 4)
    mean4 = pick(1.0, 0.0, 4)
    lines = ["### Why the light-field arm's PIV fails: the same PIV on ideal volumes\n",
             f"Ideal volumes: Gaussian blobs (sigma {I['sigma_voxels']:g} voxel) at the true particle positions, the "
             "runs' own PIV settings, scored as the runs score (RMS against the flow averaged over each window, "
             "replaced outliers included; median |error| of the vectors kept).\n",
             "| volumes | particles per final window | RMS u / v / w [voxels] | median u / v / w [voxels] | outliers |",
             "|---|---|---|---|---|"]
    for arm, name in (("lf", "LF arm (crop as run)"), ("tomo", "Tomo arm")):
        r = s[arm]
        lines.append(f"| {name}, reconstructed | {r['particles_per_final_window']:.1f} | "
                     f"{_v3(E[arm]['rms_vox'] or [math.nan] * 3)} | | {100 * E[arm]['outlier_ratio']:.1f} % |")
        lines.append(f"| {name}, ideal | {r['particles_per_final_window']:.1f} | {_v3(r['rms_vox'])} | "
                     f"{_v3(r['median_abs_vox'])} | {100 * r['outlier_ratio']:.1f} % |")
    for r in f:
        lines.append(f"| ideal, {I['crop_px'][0]} x {I['crop_px'][1]} px crop, {_ideal_label(r)} | "
                     f"{r['particles_per_final_window']:.1f} | {_v3(r['rms_vox'])} | {_v3(r['median_abs_vox'])} | "
                     f"{100 * r['outlier_ratio']:.1f} % |")
    ml, mt = M["lf"]["envelope1"], M["tomo"]["envelope1"]
    share = s["lf"]["outlier_ratio"] / E["lf"]["outlier_ratio"] if E["lf"]["outlier_ratio"] else math.nan
    wx = " x ".join(map(str, base["windows"][0]))
    wr = " x ".join(map(str, np.ones(3, int) * np.asarray(s["lf"]["windows"][0])))
    lines.append(
        "\nSub-window motion (the flow's displacement inside a final window beyond a linear fit, which a deforming "
        f"window cannot follow; RMS u / v / w over {ml['windows']} windows in the light-field grid): turbulent jet "
        f"{_v3(ml['nonlinear_vox'])} voxels in a light-field window ({' x '.join(f'{v:.2f}' for v in ml['window_mm'])} "
        f"mm), {_v3(mt['nonlinear_vox'])} in a tomographic one ({' x '.join(f'{v:.2f}' for v in mt['window_mm'])} "
        f"mm); mean flow only {_v3(M['lf']['envelope0']['nonlinear_vox'])} and "
        f"{_v3(M['tomo']['envelope0']['nonlinear_vox'])}.\n")
    lines.append(
        f"- **Before the reconstruction.** On ideal volumes of its own particles the light-field arm keeps "
        f"{pct(s['lf'])} outliers and {_v3(s['lf']['rms_vox'])} voxels; reconstructed {pct(E['lf'])} and "
        f"{_v3(E['lf']['rms_vox'] or [math.nan] * 3)}: {100 * share:.0f} % of the outlier rate is there before any "
        f"reconstruction, which then multiplies the RMS errors. The tomographic arm: {pct(s['tomo'])} ideal, "
        f"{pct(E['tomo'])} reconstructed.\n"
        f"- **The crop.** A {I['crop_px'][0]} x {I['crop_px'][1]} px crop with Table 4's own first window ({wx} in "
        f"place of the run's {wr}): {pct(base)} against {pct(s['lf'])}"
        + (": the crop and the first window explain a part." if base["outlier_ratio"] < 0.9 * s["lf"]["outlier_ratio"]
           else ": no better.") + "\n"
        f"- **The seeding.** Table 4's concentration puts {s['lf']['particles_per_final_window']:.1f} particles in a "
        f"light-field final window (the paper's rule for its simulations: 7 ~ 10) and "
        f"{s['tomo']['particles_per_final_window']:.1f} in a tomographic one (Table 4's final windows: 0.092 D x "
        f"0.095 D x 0.088 D against 0.13 D x 0.13 D x 0.12 D, 2.6 times the volume). Four times the seeding: "
        f"{pct(dense)}, {_v3(dense['rms_vox'])} voxels.\n"
        f"- **The flow.** The mean flow alone at Table 4's seeding: {pct(mean)}, {_v3(mean['rms_vox'])} voxels. The "
        "same millimetres of turbulent motion are 6.8 times more voxels at 2:2:10's 0.0116 mm lateral voxel than at "
        "the tomographic 0.079 mm: the light-field windows see sub-window motion of "
        f"{max(ml['nonlinear_vox'][:2]):.1f} voxels, as large as the ideal particle images (about "
        f"{4 * I['sigma_voxels']:g} voxels across): a window holds no single displacement to find; the tomographic "
        f"windows see {max(mt['nonlinear_vox'][:2]):.1f}.\n"
        f"- **The passes.** With the mean flow only, the paper's two passes leave u off by a median "
        f"{mean['median_abs_vox'][0]:.2f} voxels: the first pass's wide windows average the lip line's shear and one "
        "deforming pass does not undo their error. Two more passes at the final window: "
        f"{mean4['median_abs_vox'][0]:.2f} voxels and {pct(mean4)} outliers (the paper's LF-PIV: 4.1 %); with the "
        f"turbulent jet {pct(more)}, {_v3(more['rms_vox'])} voxels.\n"
        "- **Our jet, not the paper's.** The synthetic turbulence carries the developed mixing layer's intensities "
        "(0.16 U_j at the lip line) down to scales below the final window. The paper's measured jet (Re_D 2000, "
        "2.25 D, forced at 1 Hz, phase-averaged over 20 pairs) is likely transitional there, with rolled-up vortices "
        "and less sub-window motion; its 4.1 % spurious vectors are those of its own flow.")
    return "\n".join(lines)


def _exp_vectors(n_vox, windows) -> tuple[int, ...]:
    """Vectors per axis of a final window at 75 % overlap over a grid (x, y, z voxels)."""
    w = windows[-1]
    return _vectors_per_axis(n_vox, (w, w, w) if np.isscalar(w) else tuple(w))


def _experiment_rows(E: dict) -> list[Row]:
    lf, tomo = E["lf"], E["tomo"]
    rows = []
    px_lf = int(np.prod(PAPER_EXP_LF_SENSOR))
    tomo_px = tomo["cameras"].get("pixels")
    rows.append(compare_value("experiment_ltpr", "LTPR of the replica: the whole 6600 x 4400 px light-field sensor over "
                              "the four rendered tomographic images", "Sect. 3, Table 4", PAPER_EXP["ltpr"],
                              px_lf / tomo_px if tomo_px else math.nan, abs=0.005,
                              why="the paper rounds to two decimals", note=f"tomographic pixels {tomo_px}"))
    for arm, name in (("lf", "LF-PIV"), ("tomo", "Tomo-PIV")):
        pct = 100.0 * float(E[arm]["outlier_ratio"])
        rows.append(compare_value(f"experiment_{arm}_outlier_pct", f"{name} spurious vectors (UOD, replaced) in the "
                                  "replica", "Sect. 3", PAPER_EXP[f"{arm}_outlier_pct"], pct, unit="%", abs=3.0,
                                  why="3 percentage points: one instantaneous simulated field vs the paper's 20 "
                                  "experimental pairs", note="the crop's vectors only" if arm == "lf" else ""))
    ours_t = tuple(E["tomo"]["vectors_zyx"][::-1])
    rows.append(compare_trend("experiment_tomo_vectors", "Tomo-PIV vectors (x x y x z), Table 4's volume and windows",
                              "Table 4", " x ".join(map(str, PAPER_EXP["tomo_vectors"])), " x ".join(map(str, ours_t)),
                              all(abs(a - b) <= 1 for a, b in zip(ours_t, PAPER_EXP["tomo_vectors"], strict=True)),
                              tolerance="each axis within 1"))
    lf_full = _exp_vectors(PAPER_EXP_LF_GRID, [[160, 160, 32]])
    rows.append(compare_trend("experiment_lf_vectors_full", "LF-PIV vectors (x x y x z) of the whole 3300 x 2200 x 182 "
                              "grid with 160 x 160 x 32 windows at 75 % overlap (bookkeeping; the run is a crop)",
                              "Table 4", " x ".join(map(str, PAPER_EXP["lf_vectors"])), " x ".join(map(str, lf_full)),
                              all(abs(a - b) <= 1 for a, b in zip(lf_full, PAPER_EXP["lf_vectors"], strict=True)),
                              tolerance="each axis within 1",
                              note=f"the crop measured {' x '.join(map(str, lf['vectors_zyx'][::-1]))}"))
    c = E["lf_vs_tomo"]
    rows.append(compare_value("experiment_lf_tomo_correlation", "correlation of the LF-PIV and Tomo-PIV velocity "
                              "fields where they overlap (mean vector removed)", "Sect. 3", PAPER_EXP["correlation"],
                              c["r"], abs=0.05, why="the paper's 0.94 is of phase-averaged fields; ours one "
                              "instantaneous pair on the crop",
                              note=f"{c['n']} light-field vectors; RMS difference {c['rms_diff_mm_s']:.2f} mm/s"))
    crop_px = lf["cameras"].get("pixels")
    lf_full_s = lf["reconstruct_s"] / 2 * px_lf / crop_px if crop_px else math.nan
    ratio = lf_full_s / (tomo["reconstruct_s"] / 2)
    paper_ratio = PAPER_EXP["lf_reconstruct_s"] / PAPER_EXP["tomo_reconstruct_s"]
    rows.append(_time_row("experiment_time_ratio_lf_over_tomo", "LF-PIV / Tomo-PIV reconstruction time, the "
                          "replica (per frame)", paper_ratio, ratio,
                          source="Sect. 3 (4.5 h / 10.7 s)",
                          note=f"ours: the crop's DRT-MART ({lf['reconstruct_s'] / 2:.0f} s per frame, {crop_px} px) "
                          f"scaled by the pixel count to the whole sensor ({lf_full_s / 3600:.1f} h) over the whole "
                          f"volume's MLOS-SMART ({tomo['reconstruct_s'] / 2:.0f} s)"))
    for arm, name in (("lf", "LF-PIV"), ("tomo", "Tomo-PIV")):
        v = E[arm]["rms_vox"] or [math.nan] * 3
        rows.append(Row(f"experiment_{arm}_rms_vox", f"{name} RMS error against the truth in the replica (u v w pooled)",
                        "Sect. 3", "not measured (no truth in an experiment)", _num(_rms3(v)), unit="voxel",
                        note="u / v / w " + " / ".join(f"{x:.3f}" for x in v)))
    return rows


def _experiment_section(E: dict, quick: bool) -> str:
    a = E["arms"]
    lf, tomo = E["lf"], E["tomo"]
    return (
        "## The experiment replica (section 3, Table 4)\n\n"
        f"`scenes/{EXPERIMENT_SCENE}` (its `make_scene.py` docstring lists our readings): one light-field camera "
        "(5.5 um pixels, 200 mm lens at 0.0058 mm/px, PMR 14 hexagonal MLA, f-number matched) on the z axis and four "
        "480 x 320 px cameras (7.4 um, 85 mm at 0.079 mm/px, 992 mm away, 25 deg off the axis in a cross, f/11, "
        "Scheimpflug on the mid-plane), a 10 mm sheet at 532 nm, 20 um polyamide particles in water (Lorenz-Mie), "
        "0.956 particles/mm^3 (Table 4's 0.06 ppm = 0.062 ppp), the jet at Re_D 2000 (D = 20 mm) 2.25 D from the "
        "nozzle (`near_field_jet`), one pulse separation (6 ms) for both arms, 12-bit sensors with shot and read "
        "noise from one exposure.\n\n"
        "**The crop.** The paper's light-field grid (3300 x 2200 x 182 voxels) and its DRT weights (~4e10 entries "
        "at 8 rays per pixel, ~1.4 TB: 100 times the crop's) do not fit here; the light-field arm runs on "
        f"{a['lf'].get('scene.params.lf_width', 660)} x {a['lf'].get('scene.params.lf_height', 440)} px of the sensor "
        "centred on the jet's lip line (y = D/2: the core is uniform flow), the reconstruction on what that crop sees "
        "(full depth) with the particles seeded 1 mm beyond it, DRT-MART "
        f"{a['lf'].get('reconstruction.iterations', 400)} iterations at 2:2:10; the tomographic arm on the whole "
        f"volume (MLOS-SMART {a['tomo'].get('reconstruction.iterations')} iterations at 1:1:1). Windows: Table 4's "
        "64^3 -> 32^3 (Tomo) and 160 x 160 x 32 final (LF) after a 200 x 200 x 64 first pass (Table 4's 320 x 320 x "
        "64 is wider than the crop)." + (" The quick scale shrinks both arms further (3 iterations): its numbers "
                                           "exercise the code only." if quick else "") + "\n\n"
        f"Measured: LF-PIV {lf['n_vectors']} vectors, RMS error u / v / w "
        + " / ".join(f"{x:.3f}" for x in (lf["rms_vox"] or [math.nan] * 3))
        + f" voxels, reconstruction {lf['reconstruct_s']:.0f} s (two frames), render {lf['render_s']:.0f} s; "
        f"Tomo-PIV {tomo['n_vectors']} vectors, RMS error "
        + " / ".join(f"{x:.3f}" for x in (tomo["rms_vox"] or [math.nan] * 3))
        + f" voxels, reconstruction {tomo['reconstruct_s']:.0f} s, render {tomo['render_s']:.0f} s. "
        f"LF vs Tomo where they overlap: r = {E['lf_vs_tomo']['r']:.3f} over {E['lf_vs_tomo']['n']} vectors."
    )


# ---------------------------------------------------------------------- run
def _rms3(v) -> float:
    a = np.asarray(v, dtype=float)
    return float(np.sqrt(np.mean(a**2)))


def run(ctx) -> ReplicationResult:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from mitpiv.replications.lfpiv_vs_tomo import model as S

    sc = scale(ctx.quick)
    items = _items(sc, ctx.seed)
    res = ctx.map(case_point, items, key=_key, desc="cases")
    R = {}
    for it, r in zip(items, res, strict=True):
        R[("lf", it["camera"], it["pmr"]) if it["kind"] == "lf" else ("tomo", it["nc"], it["ppp"])] = r
    conv = ctx.cached(f"convergence_r{sc['convergence_random_rays']}_l{'-'.join(f'{v:g}' for v in sc['convergence_levels'])}"
                      f"_s{ctx.seed}", lambda: convergence(sc, ctx.seed))
    dc = sc["depth_crop_mm"]
    depth = ctx.cached(f"depth3_low_pmr14_c{dc[0]:g}x{dc[1]:g}_it{'-'.join(str(i) for i in sc['depth_iterations'])}"
                       f"_r{sc['rays_per_aperture_pixel']:g}_drt{sc['drt_rays_per_pixel']}_cov{S_MIN_COVERAGE:g}_t2"
                       f"_s{ctx.seed}",
                       lambda: S.lf_depth_point(S.LFCase("low", 14, *dc), iterations=sc["depth_iterations"],
                                                rays_per_aperture_pixel=sc["rays_per_aperture_pixel"],
                                                drt_rays_per_pixel=sc["drt_rays_per_pixel"],
                                                seed=1000 * ctx.seed + 98))
    rows: list[Row] = []
    curves: dict[str, Curve] = {}
    figures: list[str] = []

    # --- Table 1: LTPR and particle numbers (library bookkeeping, no run needed)
    for cam in CAMERAS:
        for nc in NCS:
            c = S.LFCase(cam, 14, 12.0)
            rows.append(compare_value(f"ltpr_{cam}_nc{nc}", f"LTPR, {LF_RES[cam]} px light-field camera vs {nc} "
                                      "tomographic cameras of 160 x 160 px", "Table 1", PAPER_LTPR[(cam, nc)],
                                      c.ltpr(nc), abs=0.005, why="the paper rounds to two decimals"))
        for pmr in PMRS:
            n = S.LFCase(cam, pmr, 12.0).n_particles()
            mx, my = LF_CAMERAS_MLA[cam][pmr]
            note = (f"0.5 x {mx} x {my} = {0.5 * mx * my:g}: the paper's {PAPER_PARTICLES[(cam, pmr)]} does not follow "
                    "from its own MLA resolution (every other column does)"
                    if round(0.5 * mx * my) != PAPER_PARTICLES[(cam, pmr)] else "")
            rows.append(compare_value(f"particles_lf_pmr{pmr}_{cam}", f"particles at 0.5 ppm, PMR {pmr}, {cam} LTPR",
                                      "Table 1", PAPER_PARTICLES[(cam, pmr)], n, abs=0.5, why="a count", note=note))
    for ppp in PPPS:
        n = S.TomoCase(4, ppp, 12.0).n_particles()
        rows.append(compare_value(f"particles_tomo_ppp{ppp:g}", f"particles at {ppp:g} ppp on 160 x 160 px", "Table 1",
                                  PAPER_PARTICLES[(ppp,)], n, abs=0.5, why="a count"))

    # --- Fig. 7: particle-centre errors
    pos = {k: r["particles_err"]["rms_mm"] for k, r in R.items()}
    for cam in CAMERAS:
        curves[f"fig7_lf_position_rms_{cam}"] = Curve(list(PMRS), {ax: [pos[("lf", cam, p)][i] for p in PMRS]
                                                                   for i, ax in enumerate("xyz")},
                                                      "PMR", "particle-centre RMS error [mm]")
    for ppp in PPPS:
        curves[f"fig7_tomo_position_rms_ppp{ppp:g}"] = Curve(list(NCS), {ax: [pos[("tomo", n, ppp)][i] for n in NCS]
                                                                         for i, ax in enumerate("xyz")},
                                                             "N_c", "particle-centre RMS error [mm]")
    for pmr in PMRS:
        lo, hi = pos[("lf", "low", pmr)], pos[("lf", "high", pmr)]
        ratio = float(np.mean([hi[0] / lo[0], hi[1] / lo[1]])) if all(np.isfinite(lo[:2] + hi[:2])) else math.nan
        rows.append(compare_value(f"lf_xy_pos_error_high_over_low_pmr{pmr}", f"x/y particle-centre RMS error, high "
                                  f"over low LTPR, PMR {pmr}", "Fig. 7c-d, Sect. 2.3", 0.5, ratio, abs=0.15,
                                  why="'nearly double the ... accuracy': read as 0.5 +- 0.15"))
    for ppp in PPPS:
        e = [_rms3(pos[("tomo", n, ppp)]) for n in NCS]
        ok = e[2] <= e[0]
        rows.append(compare_trend(f"tomo_pos_error_falls_with_nc_ppp{ppp:g}", f"Tomo-PIV particle-centre RMS error "
                                  f"(3D) at N_c 4 / 6 / 8, {ppp:g} ppp [mm]", "Fig. 7a-b", "falls with N_c",
                                  " / ".join(f"{v:.4f}" for v in e), ok, tolerance="N_c 8 below N_c 4"))
    e5 = [_rms3(pos[("tomo", n, 0.05)]) for n in NCS]
    e10 = [_rms3(pos[("tomo", n, 0.1)]) for n in NCS]
    rows.append(compare_trend("tomo_pos_error_rises_with_ppp", "Tomo-PIV particle-centre error, 0.1 over 0.05 ppp "
                              "(mean over N_c)", "Fig. 7a-b", "> 1 (denser seeding, more ghosts)",
                              float(np.mean(np.array(e10) / np.array(e5))), bool(np.mean(e10) > np.mean(e5)),
                              tolerance="> 1"))

    # --- Fig. 8: RMS velocity (displacement) errors, in voxels of each reconstruction
    piv = {k: r["piv"] for k, r in R.items()}
    for cam in CAMERAS:
        curves[f"fig8a_lf_rms_vox_{cam}"] = _uvw_curve(piv, ("lf", cam), "RMS displacement error [voxels]")
        for pmr in PMRS:
            for i, c in enumerate("uvw"):
                ours = piv[("lf", cam, pmr)]["rms_vox"][i]
                rid = f"{c}_rms_px_pmr{pmr}_{cam}"
                if (c, pmr, cam) == ("w", 14, "high"):
                    rows.append(compare_value(rid, "LF-PIV w RMS error, PMR 14, high LTPR", "Fig. 8a, Sect. 2.3",
                                              PAPER_W_RMS_PMR14_HIGH, ours, unit="voxel", abs=0.05,
                                              why="'around 0.15 pixels'", note="in z voxels (0.075 mm)"))
                else:
                    rows.append(Row(rid, f"LF-PIV {c} RMS error, PMR {pmr}, {cam} LTPR", "Fig. 8a",
                                    "plotted (no number in the text)", _num(ours), unit="voxel"))
    for ppp in PPPS:
        curves[f"fig8b_tomo_rms_vox_ppp{ppp:g}"] = _uvw_curve(piv, ("tomo", ppp), "RMS displacement error [voxels]")
        for nc in NCS:
            ours = _rms3(piv[("tomo", nc, ppp)]["rms_vox"])
            rows.append(Row(f"tomo_rms_px_nc{nc}_ppp{ppp:g}", f"Tomo-PIV RMS error (u, v, w pooled), {nc} cameras, "
                            f"{ppp:g} ppp", "Fig. 8b", "plotted (no number in the text)", _num(ours), unit="voxel",
                            note="u / v / w " + " / ".join(f"{v:.3f}" for v in piv[("tomo", nc, ppp)]["rms_vox"])))
    ideal = {k: r["piv_ideal"] for k, r in R.items()}
    for cam in CAMERAS:
        curves[f"ideal_lf_rms_vox_{cam}"] = _uvw_curve(ideal, ("lf", cam), "RMS error of PIV on ideal volumes [voxels]")
    for ppp in PPPS:
        curves[f"ideal_tomo_rms_vox_ppp{ppp:g}"] = _uvw_curve(ideal, ("tomo", ppp),
                                                              "RMS error of PIV on ideal volumes [voxels]")
    t4 = [_rms3(piv[("tomo", n, 0.05)]["rms_vox"]) for n in NCS]
    rows.append(compare_trend("tomo_rms_falls_with_nc", "Tomo-PIV RMS error at N_c 4 / 6 / 8, 0.05 ppp [voxels]",
                              "Fig. 8b", "falls with N_c", " / ".join(f"{v:.3f}" for v in t4), t4[2] <= t4[0],
                              tolerance="N_c 8 below N_c 4"))
    lo14 = _rms3(piv[("lf", "low", 14)]["rms_mm"])
    hi14 = _rms3(piv[("lf", "high", 14)]["rms_mm"])
    rows.append(compare_trend("lf_rms_falls_with_ltpr_pmr14", "LF-PIV RMS error (mm, u v w pooled), PMR 14, low / "
                              "high LTPR", "Fig. 8a", "high below low", f"{lo14:.4f} / {hi14:.4f}", hi14 < lo14,
                              tolerance="ordering"))

    # --- the crossing: smallest LTPR at which LF-PIV (PMR 14) matches Tomo-PIV (0.05 ppp), in mm
    cross_x, cross_lf, cross_tomo = [], [], []
    for nc in NCS:
        tomo_mm = _rms3(piv[("tomo", nc, 0.05)]["rms_mm"])
        found = None
        for cam in CAMERAS:  # increasing LTPR
            lf_mm = _rms3(piv[("lf", cam, 14)]["rms_mm"])
            if math.isfinite(lf_mm) and lf_mm <= tomo_mm:
                found = S.LFCase(cam, 14, 12.0).ltpr(nc)
                break
        cross_x.append(nc)
        cross_lf.append(found)
        cross_tomo.append(tomo_mm)
        rows.append(compare_value(f"ltpr_cross_nc{nc}", f"smallest LTPR at which LF-PIV (PMR 14) matches {nc}-camera "
                                  "Tomo-PIV (0.05 ppp), RMS error in mm", "Sect. 2.3", PAPER_CROSSING[nc],
                                  found if found is not None else math.nan, abs=0.01,
                                  why="the two LTPRs of the study's cameras",
                                  note=f"Tomo {tomo_mm:.4f} mm; LF low {lo14:.4f}, high {hi14:.4f} mm"
                                  + ("" if found is not None else "; LF-PIV never matches (null)")))
    curves["ltpr_crossing"] = Curve(cross_x, {"ours": [v for v in cross_lf]}, "N_c", "crossing LTPR",
                                    paper={"paper": [PAPER_CROSSING[n] for n in NCS]})

    # --- where the light-field errors sit: by depth, against the DRT-MART iterations
    its = [str(i) for i in sc["depth_iterations"]]
    zs = depth["ideal"]["z_mm"]
    curves["lf_error_by_depth_pmr14_low"] = Curve(
        zs, {**{f"u rms, {i} iterations": [r[0] for r in depth["by_iterations"][i]["rms_vox"]] for i in its},
             "u rms, ideal volumes": [r[0] for r in depth["ideal"]["rms_vox"]]},
        "vector depth z [mm] (0: the focal plane)", "RMS u error [voxels]")
    last = depth["by_iterations"][its[-1]]
    share = last["n_gross_near_focal_plane"] / last["n_gross"] if last["n_gross"] else math.nan
    rows.append(Row("lf_gross_errors_near_focal_plane_pmr14_low", f"share of the gross PIV errors (> "
                    f"{last['gross_voxels']:g} voxels) within half a window of the focal plane, LF low PMR 14, "
                    f"{its[-1]} iterations", "diagnostic", "not in the paper", _num(share),
                    note=f"{last['n_gross']} gross of {last['n_vectors']} vectors; the band holds "
                    f"{last['n_near_focal_plane']} vectors; median |error| u / v / w "
                    + " / ".join(f"{v:.2f}" for v in last["median_abs_vox_all"]) + " voxels, RMS "
                    + " / ".join(f"{v:.2f}" for v in last["rms_vox_all"])
                    + "; by iterations " + ", ".join(f"{i}: RMS u {depth['by_iterations'][i]['rms_vox_all'][0]:.2f}, "
                                                     f"{depth['by_iterations'][i]['n_gross']} gross" for i in its)))

    tv = depth["trim_voxels"]
    rows.append(Row("lf_hot_voxels_on_boundary_pmr14_low", f"share of the 100 brightest voxels' squared intensity within "
                    f"{tv} voxels of the grid's lateral boundary, LF low PMR 14, {its[-1]} iterations", "diagnostic",
                    "not in the paper", _num(last["hot_energy_share_at_boundary"]),
                    note="by iterations " + ", ".join(f"{i}: {depth['by_iterations'][i]['hot_energy_share_at_boundary']:.2f}"
                                                      for i in its)))
    rows.append(Row("lf_rms_vox_boundary_zeroed_pmr14_low", f"LF low PMR 14 PIV RMS error (u v w pooled) with the "
                    f"{tv} outermost voxels in x and y set to 0, {its[-1]} iterations", "diagnostic", "not in the paper",
                    _num(_rms3(last["trimmed"]["rms_vox_all"])), unit="voxel",
                    note="raw vs zeroed boundary, u / v / w: " + "; ".join(
                        f"{i} it: " + " / ".join(f"{v:.2f}" for v in depth["by_iterations"][i]["rms_vox_all"]) + " vs "
                        + " / ".join(f"{v:.2f}" for v in depth["by_iterations"][i]["trimmed"]["rms_vox_all"])
                        for i in its) + "; ideal " + " / ".join(f"{v:.2f}" for v in depth["ideal"]["rms_vox_all"])))

    rows.append(Row("lf_rms_vox_edge_dropped_pmr14_low", f"LF low PMR 14 PIV RMS error (u v w pooled), the field's "
                    f"edge dropped from DRT-MART (min_coverage {depth['min_coverage']:g}, as every light-field case of "
                    f"this run), {its[-1]} iterations", "diagnostic", "not in the paper",
                    _num(_rms3(last["masked"]["rms_vox_all"])), unit="voxel",
                    note="u / v / w by iterations: " + "; ".join(
                        f"{i} it: " + " / ".join(f"{v:.2f}" for v in depth["by_iterations"][i]["masked"]["rms_vox_all"])
                        for i in its) + "; ideal " + " / ".join(f"{v:.2f}" for v in depth["ideal"]["rms_vox_all"])))

    # --- Table 3: reconstruction times, extrapolated linearly to the full sensors / volumes
    def full_time(key):
        r = R[key]
        f = (r["full_pixels"] / r["pixels"]) if key[0] == "lf" else (r["full_voxels"] / r["voxels"])
        return r["reconstruct_s_per_frame"] * f

    base = full_time(("tomo", 4, 0.05))
    # (result key, Table 3 key, row id, what, curve label): the light-field cases, then Tomo-PIV's
    cases = [(("lf", cam, pmr), ("lf", pmr, cam), f"time_ratio_lf_pmr{pmr}_{cam}",
              f"LF-PIV reconstruction time / 4-camera Tomo-PIV, PMR {pmr}, {cam} LTPR", f"LF {pmr} {cam}")
             for cam in CAMERAS for pmr in PMRS]
    cases += [(("tomo", nc, ppp), ("tomo", nc, ppp), f"time_ratio_tomo_nc{nc}_ppp{ppp:g}",
               f"Tomo-PIV reconstruction time / 4-camera, {nc} cameras, {ppp:g} ppp", f"Tomo {nc} {ppp:g}")
              for nc in NCS for ppp in PPPS]
    tr_x, tr_ours, tr_paper = [], [], []
    for key, paper_key, rid, what, label in cases:
        ours = full_time(key) / base
        paper = PAPER_TABLE_3[paper_key]
        rows.append(_time_row(rid, what, paper, ours))
        tr_x.append(label)
        tr_ours.append(ours)
        tr_paper.append(paper)
    curves["table3_time_ratio"] = Curve(tr_x, {"ours": tr_ours}, "case", "time / 4-camera Tomo-PIV",
                                        paper={"paper": tr_paper})
    lf_order = [full_time(("lf", "low", p)) for p in PMRS]
    rows.append(compare_trend("time_lf_pmr14_fastest_low", "LF-PIV time ordering over PMR 7 / 14 / 28, low LTPR "
                              "(ratios)", "Table 3", "PMR 14 fastest; PMR 7 slowest",
                              " / ".join(f"{v / base:.2f}" for v in lf_order),
                              bool(lf_order[1] <= min(lf_order) and lf_order[0] >= max(lf_order)),
                              tolerance="ordering"))

    # --- image convergence (the paper's 5 million rays)
    curves["lf_image_convergence"] = Curve(conv["rays"], {"rel_l2_vs_monte_carlo": conv["rel_l2"]},
                                           "stratified rays per particle", "relative L2 difference")
    used = sc["rays_per_aperture_pixel"]
    k_used = S.rays_per_particle(S.lf_camera(S.LFCase("low", 14, 2.4)), used)
    i_used = conv["levels"].index(used) if used in conv["levels"] else len(conv["levels"]) - 1
    rows.append(compare_value("lf_image_rel_l2_vs_5M_rays", f"relative L2 difference of our stratified image "
                              f"({conv['rays'][i_used]} rays, PMR 14) from a {conv['random_rays']:,}-ray Monte Carlo image",
                              "Sect. 2.1 (5 million rays)", 0.0, conv["rel_l2"][i_used], abs=max(0.05, 3 * conv["reference_noise"]),
                              why="5 % or 3x the Monte Carlo image's own noise",
                              note=f"Monte Carlo noise {conv['reference_noise']:.4f}; this run renders with {k_used} "
                              "rays per PMR-14 particle"))

    # --- figures
    fig, axes = plt.subplots(1, 3, figsize=(14, 4))
    for cam, ls in (("low", "-"), ("high", "--")):
        for i, c in enumerate("uvw"):
            axes[0].plot(PMRS, [piv[("lf", cam, p)]["rms_vox"][i] for p in PMRS], "o" + ls, label=f"{c} {cam}")
    axes[0].plot([14], [PAPER_W_RMS_PMR14_HIGH], "k*", ms=12, label="paper w, PMR 14 high")
    axes[0].set_xlabel("PMR")
    axes[0].set_ylabel("RMS error [voxels]")
    axes[0].set_title("Fig. 8a: LF-PIV")
    axes[0].legend(fontsize=6)
    for ppp, ls in ((0.05, "-"), (0.1, "--")):
        for i, c in enumerate("uvw"):
            axes[1].plot(NCS, [piv[("tomo", n, ppp)]["rms_vox"][i] for n in NCS], "o" + ls, label=f"{c} {ppp:g} ppp")
    axes[1].set_xlabel("N_c")
    axes[1].set_title("Fig. 8b: Tomo-PIV")
    axes[1].legend(fontsize=6)
    axes[2].semilogy(range(len(tr_x)), tr_paper, "ks", label="paper (TITAN X)")
    axes[2].semilogy(range(len(tr_x)), tr_ours, "ro", label="ours (CPU, extrapolated)")
    axes[2].set_xticks(range(len(tr_x)))
    axes[2].set_xticklabels(tr_x, rotation=70, fontsize=6)
    axes[2].set_title("Table 3: time / 4-camera Tomo")
    axes[2].legend(fontsize=7)
    fig.tight_layout()
    figures.append(ctx.figure(fig, "fig8_table3.png"))
    fig, ax = plt.subplots(figsize=(5, 3.5))
    ax.loglog(conv["rays"], conv["rel_l2"], "o-", label="stratified vs Monte Carlo")
    ax.axhline(conv["reference_noise"], color="k", ls=":", label="Monte Carlo noise")
    ax.set_xlabel("rays per particle")
    ax.set_ylabel("relative L2 difference")
    ax.legend(fontsize=7)
    fig.tight_layout()
    figures.append(ctx.figure(fig, "lf_image_convergence.png"))
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8), sharey=True)
    for k, comp in enumerate("uvw"):
        for i in its:
            axes[k].plot(zs, [r[k] for r in depth["by_iterations"][i]["rms_vox"]], "o-", label=f"{i} iterations")
        axes[k].plot(zs, [r[k] for r in depth["by_iterations"][its[-1]]["trimmed"]["rms_vox"]], "s:",
                     label=f"{its[-1]} iterations, boundary zeroed")
        axes[k].plot(zs, [r[k] for r in depth["by_iterations"][its[-1]]["masked"]["rms_vox"]], "^-", lw=2,
                     label=f"{its[-1]} iterations, field edge dropped (this run)")
        axes[k].plot(zs, [r[k] for r in depth["ideal"]["rms_vox"]], "k--", label="ideal volumes")
        axes[k].axvline(0.0, color="grey", lw=0.8)
        axes[k].set_xlabel("vector depth z [mm] (0: focal plane)")
        axes[k].set_title(f"{comp}")
    axes[0].set_ylabel("RMS error [voxels]")
    axes[0].set_yscale("log")
    axes[0].legend(fontsize=6)
    fig.suptitle("LF-PIV, low LTPR, PMR 14: PIV error by depth and DRT-MART iterations")
    fig.tight_layout()
    figures.append(ctx.figure(fig, "lf_error_by_depth.png"))

    est_full, est_quick = cost_estimate(False), cost_estimate(True)
    # --- the experiment replica (section 3, Table 4)
    arms = experiment_arms(ctx.quick, ctx.seed)
    E = ctx.cached(f"experiment_{'quick' if ctx.quick else 'full'}_{_arm_key(arms)}",
                   lambda: experiment_summary(ctx, ctx.quick))
    rows.extend(_experiment_rows(E))
    ideal_key = hashlib.sha1(json.dumps([IDEAL_FACTORS_QUICK if ctx.quick else IDEAL_FACTORS_FULL,
                                         IDEAL_SEEDING_FACTORS, IDEAL_SIGMA_VOXELS]).encode()).hexdigest()[:6]
    ideal = ctx.cached(f"experiment_ideal_{'quick' if ctx.quick else 'full'}_{_arm_key(arms)}_{ideal_key}_s{ctx.seed}",
                       lambda: experiment_ideal(ctx, arms, ctx.quick))
    motion = ctx.cached(f"experiment_subwindow_{_arm_key(arms)}_s{ctx.seed}", lambda: experiment_subwindow(ctx, arms))
    rows.extend(_ideal_rows(E, ideal))
    vkey = f"{'quick' if ctx.quick else 'full'}_{_arm_key(variant_arms(arms))}"
    V = ctx.cached(f"experiment_mean4_{vkey}", lambda: experiment_summary(ctx, ctx.quick, "mean4"))
    V_ideal = ctx.cached(f"experiment_mean4_ideal_{vkey}_s{ctx.seed}", lambda: {
        arm: v[0] for arm, v in _same_particles(ctx, variant_arms(arms), _arm_key(arms), "mean4").items()})
    rows.extend(_variant_rows(V, V_ideal))
    for arm, name in (("lf", "LF-PIV"), ("tomo", "Tomo-PIV")):
        m = motion[arm]["envelope1"]
        rows.append(Row(f"experiment_{arm}_subwindow_motion_vox", f"{name}: the jet's displacement inside a final window "
                        "beyond a linear fit (RMS u v w pooled), the replica", "diagnostic", "not in the paper",
                        _num(_rms3(m["nonlinear_vox"])), unit="voxel",
                        note=f"u / v / w {_v3(m['nonlinear_vox'])}; spread about the window mean "
                        f"{_v3(m['spread_vox'])}; mean flow only {_v3(motion[arm]['envelope0']['nonlinear_vox'])}"))
    lab = [_ideal_label(r).replace(", ", "\n") for r in ideal["factors"]]
    fig, axes = plt.subplots(1, 2, figsize=(13, 4.2))
    xs = np.arange(len(lab))
    for i, comp in enumerate("uvw"):
        axes[0].bar(xs + (i - 1) * 0.27, [r["rms_vox"][i] for r in ideal["factors"]], 0.27, label=comp)
    axes[0].set_ylabel("RMS error [voxels]")
    axes[0].set_yscale("log")
    axes[1].bar(xs, [100 * r["outlier_ratio"] for r in ideal["factors"]], 0.6, color="grey")
    axes[1].axhline(PAPER_EXP["lf_outlier_pct"], color="k", ls="--", label="paper LF-PIV 4.1 %")
    axes[1].set_ylabel("outliers [%]")
    for ax in axes:
        ax.set_xticks(xs)
        ax.set_xticklabels(lab, fontsize=6)
        ax.legend(fontsize=7)
    fig.suptitle(f"Replica LF arm, PIV on ideal volumes ({ideal['crop_px'][0]} x {ideal['crop_px'][1]} px crop, "
                 "Table 4 windows): seeding, turbulence, passes")
    fig.tight_layout()
    figures.append(ctx.figure(fig, "experiment_ideal_factors.png"))
    c = E["lf_vs_tomo"]
    if c.get("sample_a"):
        a, b = np.asarray(c["sample_a"]), np.asarray(c["sample_b"])
        fig, axes = plt.subplots(1, 3, figsize=(12, 4))
        for i, (ax, comp) in enumerate(zip(axes, "uvw", strict=True)):
            ax.plot(b[:, i], a[:, i], ".", ms=3, alpha=0.5)
            lim = [min(a[:, i].min(), b[:, i].min()), max(a[:, i].max(), b[:, i].max())]
            ax.plot(lim, lim, "k-", lw=0.8)
            ax.set_xlabel(f"Tomo-PIV {comp} [mm/s]")
            ax.set_ylabel(f"LF-PIV {comp} [mm/s]")
        fig.suptitle(f"Experiment replica: LF-PIV vs Tomo-PIV where they overlap (r = {c['r']:.3f}, paper 0.94)")
        fig.tight_layout()
        figures.append(ctx.figure(fig, "experiment_lf_vs_tomo.png"))
    replica = "\n\n".join([_experiment_section(E, ctx.quick), _ideal_section(E, ideal, motion), _variant_section(V, V_ideal)])
    sections = [_method(sc, R, conv, est_full, est_quick, ctx), _error_table(R), replica,
                _disagreements(ctx, R, depth, E)]
    for c in curves.values():
        c.y = {k: [None if (v is None or not math.isfinite(v)) else v for v in ys] for k, ys in c.y.items()}
    return ReplicationResult(rows=rows, curves=curves, sections=sections, figures=figures)


LF_RES = {"low": "800 x 800", "high": "1600 x 1600"}


def _mla():
    from mitpiv.replications.lfpiv_vs_tomo.model import LF_CAMERAS

    return {k: v["mla"] for k, v in LF_CAMERAS.items()}


LF_CAMERAS_MLA = _mla()


def _num(v):
    return None if v is None or not math.isfinite(float(v)) else float(v)


def _uvw_curve(res, arm, ylabel: str) -> Curve:
    """The u, v, w RMS errors [voxels] (``res[key]["rms_vox"]``) of one arm along its sweep:
    ``("lf", cam)`` over the PMRs, ``("tomo", ppp)`` over the camera counts."""
    if arm[0] == "lf":
        xs, key, xlabel = PMRS, lambda pmr: ("lf", arm[1], pmr), "PMR"
    else:
        xs, key, xlabel = NCS, lambda nc: ("tomo", nc, arm[1]), "N_c"
    return Curve(list(xs), {c: [res[key(x)]["rms_vox"][i] for x in xs] for i, c in enumerate("uvw")}, xlabel, ylabel)


def _time_row(rid, quantity, paper, ours, *, source: str = "Table 3",
              note: str = "ours: per-frame CPU time of the crop scaled linearly to the full sensor / volume") -> Row:
    ok = bool(math.isfinite(ours) and ours > 0 and abs(math.log(ours / paper)) <= math.log(TIME_FACTOR))
    return compare_trend(rid, quantity, source, f"{paper:g}", _num(ours), ok,
                         tolerance=f"within a factor {TIME_FACTOR:g} (other hardware and code)", note=note)


def _v3(v) -> str:
    return " / ".join("nan" if x is None or not math.isfinite(float(x)) else f"{float(x):.2f}" for x in v)


def _disagreements(ctx, R, depth, E) -> str:
    """The findings, with the run's own numbers."""
    quick = ("In the quick scale the crops are a few lenslets wide (1.2 / 0.6 mm), the reconstructions run a few "
             "iterations and the windows are clipped to the crop: its errors, crossings and time ratios exercise the "
             "code path and are not results.\n\n" if ctx.quick else "")
    its = list(depth["by_iterations"])
    last = depth["by_iterations"][its[-1]]
    t05 = [R[("tomo", n, 0.05)] for n in NCS]
    t10 = [R[("tomo", n, 0.1)] for n in NCS]
    lf = {(c, p): R[("lf", c, p)] for c in CAMERAS for p in PMRS}
    c = E["lf_vs_tomo"]
    return (
        "## Disagreements and their causes\n\n" + quick +
        "- `particles_lf_pmr28_low`: 0.5 ppm on the table's 29 x 33 lenslets is 478 particles; the paper prints 470 "
        "(every other column of its Table 1 is 0.5 x its MLA resolution).\n"
        "- **The light-field reconstructions' edge.** Left alone, DRT-MART puts the brightest voxels of a cropped grid "
        "on its lateral boundary, in the planes near the focal plane: the voxels whose ray cones the sensor catches "
        "only in part explain the light their missing rays would have (diagnostic row "
        f"`lf_hot_voxels_on_boundary_pmr14_low`: {last['hot_energy_share_at_boundary']:.0%} of the 100 brightest "
        f"voxels' squared intensity in the {depth['trim_voxels']} outermost voxels after {its[-1]} iterations). The "
        "un-normalised FFT correlation locks onto them; for PMR 14 and 28 one first-pass window spans the crop's "
        "width, so a spurious first-pass peak becomes every second-pass vector's predictor and the universal outlier "
        "detection sees a consistent, wrong field. On LF low PMR 14 ("
        + " x ".join(f"{v:g}" for v in depth["crop_mm"]) + " mm), u / v / w RMS errors by iterations, "
        "left alone -> boundary zeroed -> field edge dropped from the reconstruction (min_coverage "
        f"{depth['min_coverage']:g}): "
        + "; ".join(f"{i}: {_v3(depth['by_iterations'][i]['rms_vox_all'])} -> "
                    f"{_v3(depth['by_iterations'][i]['trimmed']['rms_vox_all'])} -> "
                    f"{_v3(depth['by_iterations'][i]['masked']['rms_vox_all'])}" for i in its)
        + f" voxels (ideal volumes {_v3(depth['ideal']['rms_vox_all'])}). Every light-field case of this run drops "
        "the field's edge (`mitpiv.replications.lfpiv_vs_tomo.model.MIN_COVERAGE`; particles there are then not reconstructed, which the "
        "detection rates show). The crops make the artefact dominant (every window touches the edge); the paper's "
        "whole sensor has it only at its borders, and its own DRT-MART may treat them otherwise.\n"
        f"- **Iterations.** On the same images and weights (left alone), gross errors (> {last['gross_voxels']:g} "
        "voxels) by DRT-MART iterations: "
        + ", ".join(f"{i} iterations {depth['by_iterations'][i]['n_gross']}" for i in its)
        + f" of ~{last['n_vectors']} vectors ({last['n_gross_near_focal_plane']} of the {last['n_gross']} at "
        f"{its[-1]} iterations within half a window of the focal plane); the median |error| "
        + ", ".join(f"{i}: {_v3(depth['by_iterations'][i]['median_abs_vox_all'])}" for i in its) + " voxels.\n"
        "- **The flow.** The ideal-volume column of the error table is the error of the windows and the flow's "
        "variation inside them, before any reconstruction: the turbulent mixing layer at the lip line (Bell & Mehta "
        "r.m.s., L11 = 0.4 delta_w) leaves LF low PMR 14 "
        f"{_v3(lf[('low', 14)]['piv_ideal']['rms_vox'])} voxels and Tomo (0.05 ppp) "
        f"{_v3(t05[0]['piv_ideal']['rms_vox'])}, far above the paper's 0.15 px: the paper's DNS at Re_D 2500 one "
        "diameter from the nozzle is likely transitional, with much less sub-window variation.\n"
        "- **Tomo-PIV, seeding.** Table 2 gives 0.1 ppp half the window of 0.05 ppp (16^3 against 32^3): on ideal "
        f"volumes {_v3(t10[0]['piv_ideal']['rms_vox'])} against {_v3(t05[0]['piv_ideal']['rms_vox'])} voxels (N_c 4), "
        "and the reconstructions follow (0.1 ppp: " + "; ".join(_v3(r["piv"]["rms_vox"]) for r in t10)
        + "; 0.05 ppp: " + "; ".join(_v3(r["piv"]["rms_vox"]) for r in t05) + " for N_c 4 / 6 / 8), so our 0.1 ppp "
        "is the more accurate where the paper finds it slightly worse (ghosts): our ghosts cost less than the "
        "smaller windows gain in this sheared flow.\n"
        "- **Table 3**: the paper's GPU times include its implementation's per-pixel ray tracing inside every "
        "DRT-MART iteration; ours builds the DRT weight matrix once per camera and grid and iterates on the sparse "
        "matrix, so the light-field cases are cheaper relative to SMART than on the paper's GPU.\n"
        f"- **The experiment replica.** LF and Tomo agree to r = {c['r']:.2f} where they overlap ({c['n']} vectors; "
        "the paper 0.94 on phase-averaged fields of the whole volume, with the flow's mean removed here); spurious "
        f"vectors {100 * E['lf']['outlier_ratio']:.1f} % (LF, on the crop) and {100 * E['tomo']['outlier_ratio']:.1f} "
        "% (Tomo) against the paper's 4.1 % and 5.2 %; the section \"Why the light-field arm's PIV fails\" above "
        "measures the causes on ideal volumes.")


def _error_table(R) -> str:
    lines = ["## PIV errors: reconstructed vs ideal volumes\n",
             "RMS displacement error [voxels] (u / v / w) of the PIV on the reconstructions and on ideal volumes "
             "(Gaussian blobs at the true positions; the error of the windows and the flow's sub-window variation "
             "alone), valid vectors, outlier ratio of the reconstructions' PIV.\n",
             "| case | voxel [mm] | windows | reconstructed | ideal | vectors | outliers |", "|---|---|---|---|---|---|---|"]
    for k, r in R.items():
        name = f"LF {k[1]} PMR {k[2]}" if k[0] == "lf" else f"Tomo N_c {k[1]}, {k[2]:g} ppp"
        f = " / ".join(f"{v:.2f}" for v in r["piv"]["rms_vox"])
        i = " / ".join(f"{v:.2f}" for v in r["piv_ideal"]["rms_vox"])
        vox = " x ".join(f"{v:g}" for v in r["voxel_mm"])
        w = " -> ".join("x".join(str(x) for x in ww) for ww in r["piv"]["windows"])
        lines.append(f"| {name} | {vox} | {w} | {f} | {i} | {r['piv']['n_valid']} | {r['piv']['outlier_ratio']:.2f} |")
    return "\n".join(lines)


def _method(sc, R, conv, est_full, est_quick, ctx) -> str:
    lf = [f"{k[1]} PMR {k[2]}: {' x '.join(str(v) for v in r['sensor_px'])} px crop, {r['particles']} particles, grid {r['grid']}, "
          f"{r['rays_per_particle']} rays/particle, {r['weight_entries']:,} DRT weights"
          for k, r in R.items() if k[0] == "lf"]
    return (
        "## Method and decisions\n\n"
        "Set-up and readings of what the paper leaves open: see `mitpiv.replications.lfpiv_vs_tomo.model` (module docstring): "
        "12 x 12 x 10 mm volume; light-field cameras at magnification 1 (Table 1's p_p is both the pixel and the "
        "object-space pixel), 200 mm main lens at 1:1, image-side f/4 matched by f/4 hexagonal lenslets of pitch "
        "PMR x p_p with the table's MLA resolutions; tomographic pinholes 946.5 mm away (image distance 93.4 mm, "
        "0.075 mm/px) with viewing directions spread over 180 deg in the x-z plane; 0.5 ppm and 0.05 / 0.1 ppp; "
        "near-field jet at Re_D 2500 (D = 40 mm, water, 62.5 mm/s) with the volume 1 D downstream on the lip line "
        "(`mitpiv.physics.jet.NearFieldJet`: tanh mean profile with the Brown & Roshko spreading rate, "
        "mixing-layer r.m.s. of Bell & Mehta, divergence-free synthetic turbulence); DRT-MART at 2:2:10 and "
        "MLOS-SMART at 1:1:1; particle centres by a 3^3 centroid; two-pass PIV with Table 2's windows, 75 % "
        "overlap, against the flow box-averaged over the final window. Errors are in voxels of each reconstruction "
        "(the PIV's own unit; the paper's 'pixels'), and in mm for the LF-vs-Tomo crossing (the only unit the two "
        "share).\n\n"
        f"**Scale** ({'quick' if ctx.quick else 'full'}): light-field crops {sc['lf_crop_mm']} mm (central "
        f"squares; full depth), DRT-MART {sc['lf_iterations']} iterations with {sc['drt_rays_per_pixel']} rays per "
        f"pixel; tomographic y slab {sc['tomo_crop_y_mm']} mm, SMART {sc['tomo_iterations']} iterations; windows "
        f"x {sc['window_scale']:g} of Table 2 (clipped to the volume). Cases: " + "; ".join(lf) + ".\n\n"
        f"**Rays.** The paper traces 5 million random rays per particle; we use a jittered stratified grid over "
        f"the aperture. Against a {conv['random_rays']:,}-ray Monte Carlo image of one PMR-14 particle (whose own "
        f"noise is {conv['reference_noise']:.4f} relative L2): "
        + ", ".join(f"{k} rays {e:.4f}" for k, e in zip(conv["rays"], conv["rel_l2"], strict=True)) + ".\n\n"
        f"**Cost.** Estimated single-core time: full {est_full['cpu_s'] / 3600:.1f} h (light field "
        f"{est_full['lf_s'] / 3600:.1f} h, tomography {est_full['tomo_s'] / 3600:.1f} h, the experiment replica "
        f"{est_full['experiment_s'] / 3600:.1f} h; "
        f"{est_full['cpu_s'] / 7200:.1f} h on 2 workers), quick {est_quick['cpu_s']:.0f} s.\n\n"
        "**Table 3.** Our times are CPU (Numba) per frame of the crop, scaled linearly with the pixel count (light "
        "field) or the voxel count (tomography) to the paper's full sizes, normalised by the four-camera rig at "
        "0.05 ppp."
    )


#: results of the paper used as model inputs (REPLICATION.md, point 8). The simulation's
#: set-up is the paper's (Tables 1, 2 and 4: sensors, MLA resolutions, seeding, windows,
#: grids) and none of its results (errors, crossings, counts, times, outlier rates, the
#: correlation) feeds a computed point: they are comparators only. The one paper number a row
#: is computed from without the simulation:
INPUTS_FROM_PAPER = {
    "table4_lf_grid": "Table 4's light-field reconstruction grid, 3300 x 2200 x 182 voxels (PAPER_EXP_LF_GRID, the "
                      "paper's whole sensor at 2:2:10): experiment_lf_vectors_full counts its windows; our run "
                      "reconstructs a crop and never uses it",
}

_INFO_FIG8 = Kind("info", "Fig. 8 plots it but the text gives no number; shown for context (the one number, w at PMR "
                  "14 and high LTPR, is the physics row w_rms_px_pmr14_high).")
_DIAGNOSIS = Kind("info", "A diagnosis of our light-field PIV errors (edge, iterations, ideal volumes, seeding, "
                  "turbulence, passes, sub-window motion); the paper has no value for it.")
_TIMES = ("The relative cost of two implementations (our CPU code builds the DRT weights once; the paper's GPU code "
          "traces rays in every iteration), normalised by our 4-camera SMART: not a property of the images.")
#: each row's kind (REPLICATION.md, point 7); rows not listed are physics. Order matters for the
#: patterns (the first that matches wins; an exact id wins over all)
KINDS = {
    # ---------------------------------------------------------------- physics, with caveats
    "ltpr_cross_nc*": Kind(
        "physics", "The value can only be one of this N_c's two Table 1 LTPRs (or null), so what is tested is an "
        "ordering, LF low (PMR 14) > Tomo-PIV (N_c, 0.05 ppp) >= LF high, in mm: it could fail, but the three rows "
        "share the same two light-field errors, and in mm the high camera's voxels are half the low's."),
    "lf_rms_falls_with_ltpr_pmr14": Kind(
        "physics", "Only PMR 14 is compared, in mm, where the high camera's voxels are half the low's: the ordering "
        "holds unless its error in voxels is twice the low's. The paper states the fall for every PMR (point 10)."),
    "lf_xy_pos_error_high_over_low_pmr*": Kind(
        "physics", "The high camera's voxels are half the low's (Table 2), so a centroid error that is a fixed "
        "fraction of a voxel gives 0.5 by itself."),
    "tomo_rms_falls_with_nc": Kind(
        "physics", "Compared at 0.05 ppp only; Fig. 8b shows both seedings (0.1 ppp: the tomo_rms_px_*_ppp0.1 "
        "rows)."),
    "w_rms_px_pmr14_high": Kind("physics", "The paper's 'pixels' read as voxels of the light-field reconstruction "
                                "(w: 0.075 mm)."),
    "time_ratio_lf_*": Kind("physics", _TIMES),
    "time_lf_pmr14_fastest_low": Kind("physics", _TIMES),
    "experiment_time_ratio_lf_over_tomo": Kind(
        "physics", "Our CPU DRT-MART on a crop scaled by the pixel count over our CPU SMART, against the paper's GPU: "
        "the implementations' relative cost, not the images'."),
    "experiment_lf_tomo_correlation": Kind(
        "physics", "The paper's 0.94 is of phase-averaged fields (20 pairs of its forced jet); ours is one "
        "instantaneous pair of a synthetic turbulent jet on the light-field crop, the mean vector removed."),
    # ---------------------------------------------------------------- definitions: arithmetic on the paper's tables
    "ltpr_*": Kind("definition", "LTPR = light-field pixels / (N_c x 160 x 160 px): the paper's own arithmetic on "
                   "Table 1's camera sizes; no simulation enters."),
    "particles_lf_*": Kind("definition", "0.5 particles per microlens x Table 1's MLA resolution: the paper's own "
                           "arithmetic (PMR 28, low LTPR: the paper prints 470 for 0.5 x 29 x 33 = 478)."),
    "particles_tomo_*": Kind("definition", "ppp x 160 x 160 px: the paper's own arithmetic on Table 1."),
    "time_ratio_tomo_nc4_ppp0.05": Kind("definition", "The normalisation: our 4-camera, 0.05 ppp time over itself, 1 "
                                        "by definition (as the paper's)."),
    "experiment_ltpr": Kind("definition", "6600 x 4400 px over the four rendered 480 x 320 px cameras: Table 4's "
                            "own arithmetic on its camera sizes, which the replica's cameras are set to."),
    "experiment_tomo_vectors": Kind(
        "definition", "The vector count of Table 4's 480 x 320 x 130-voxel grid with its 32-voxel final window at 75 % "
        "overlap, the grid and windows the replica's tomographic arm is set to: it holds for any images."),
    "experiment_lf_vectors_full": Kind(
        "definition", "The vector count of Table 4's whole 3300 x 2200 x 182-voxel grid with 160 x 160 x 32 windows at "
        "75 % overlap, from the paper's numbers alone (our run is a crop).", ("table4_lf_grid",)),
    # ---------------------------------------------------------------- info: could not have failed
    "time_ratio_tomo_*": Kind(
        "info", "Could not have failed: SMART's cost grows with cameras x voxels x iterations, so any implementation "
        "gives about N_c / 4 (1 to 2), inside the factor-3 band around the paper's 1.01-1.37."),
    "lf_image_rel_l2_vs_5M_rays": Kind(
        "info", "A check of our stratified rays against our own Monte Carlo image with the paper's 5 million rays; "
        "the paper reports no number (0 stands for 'the same image'): it verifies the renderer, not a result."),
    # ---------------------------------------------------------------- info: not compared
    "[uvw]_rms_px_pmr*": _INFO_FIG8,
    "tomo_rms_px_*": _INFO_FIG8,
    "lf_gross_errors_*": _DIAGNOSIS,
    "lf_hot_voxels_*": _DIAGNOSIS,
    "lf_rms_vox_*": _DIAGNOSIS,
    "experiment_*_ideal_rms_vox": _DIAGNOSIS,
    "experiment_ideal_*": _DIAGNOSIS,
    "experiment_*_subwindow_motion_vox": _DIAGNOSIS,
    "experiment_*_rms_vox": Kind("info", "The error against the simulated truth: an experiment has none, so the "
                                 "paper has no value."),
    "experiment_*_particles_per_final_window": Kind(
        "info", "Concentration x final-window volume, arithmetic on the replica's Table 4 set-up; the paper's 7 ~ 10 "
        "is its sizing rule for the simulations, not a measurement of the experiment."),
    "experiment_mean4_*": Kind(
        "info", "The replica re-run with the jet's mean flow only and two more passes, a diagnosis of the light-field "
        "arm; the paper's value is of its measured jet with two passes, so not compared."),
}


STUDY = Study(
    name="lfpiv-vs-tomo",
    paper="001_9c7427d46b54a57a.txt",
    title="Single-camera light-field PIV vs tomographic PIV: PMR, LTPR, camera count, seeding",
    run=run,
    required_ids=("ltpr_cross_nc4", "ltpr_cross_nc6", "ltpr_cross_nc8", "w_rms_px_pmr14_high",
                  "tomo_rms_px_nc4_ppp0.05", "time_ratio_lf_pmr7_low", "time_ratio_lf_pmr14_high",
                  "ltpr_high_nc4", "ltpr_low_nc8", "lf_image_rel_l2_vs_5M_rays", "experiment_ltpr",
                  "experiment_lf_tomo_correlation", "experiment_time_ratio_lf_over_tomo",
                  "lf_hot_voxels_on_boundary_pmr14_low", "lf_rms_vox_boundary_zeroed_pmr14_low",
                  "lf_rms_vox_edge_dropped_pmr14_low"),
    describe="LF-PIV (800/1600 px, PMR 7/14/28, DRT-MART) vs 4/6/8-camera Tomo-PIV (MLOS-SMART) on a round jet",
    kinds=KINDS,
    inputs_from_paper=INPUTS_FROM_PAPER,
)
