"""The lfpiv-vs-tomo replication (Shi et al., seed paper 001): its quick run (schema, required
ids) and the pieces of the simulation against the paper's Tables 1-2 and independent
formulas written afresh."""

import math

import numpy as np
import pytest

from mitpiv.errors import ConfigError
from mitpiv.physics.jet import BROWN_ROSHKO_SPREADING, MIXING_LAYER_RMS, NearFieldJet
from mitpiv.replications.frame import RESULTS_KEYS, replicate
from mitpiv.replications.lfpiv_vs_tomo import model as S
from mitpiv.replications.lfpiv_vs_tomo.study import STUDY, cost_estimate

from .helpers import assert_second_edition, committed_rows


def test_quick_run_schema_and_ids(tmp_path):
    res = replicate("lfpiv-vs-tomo", tmp_path, quick=True)
    assert set(RESULTS_KEYS) <= set(res)
    assert_second_edition(res, tmp_path)
    assert res["scale"] == "quick" and res["study"] == "lfpiv-vs-tomo"
    ids = [r["id"] for r in res["rows"]]
    assert len(ids) == len(set(ids))
    assert set(STUDY.required_ids) <= set(ids)
    rows = {r["id"]: r for r in res["rows"]}
    for rid in ("w_rms_px_pmr14_high", "tomo_rms_px_nc4_ppp0.05", "time_ratio_lf_pmr7_low", "time_ratio_lf_pmr14_high",
                "lf_image_rel_l2_vs_5M_rays"):
        assert rows[rid]["ours"] is not None and rows[rid]["ours"] > 0, rid
    for rid in ("ltpr_cross_nc4", "ltpr_cross_nc6", "ltpr_cross_nc8"):  # an LTPR of the study, or null (never)
        assert rows[rid]["ours"] is None or rows[rid]["ours"] in (25.0, 100 / 6, 12.5, 6.25, 25 / 6, 3.125), rid
    assert rows["ltpr_high_nc6"]["ours"] == pytest.approx(100 / 6, rel=1e-12)
    assert rows["time_ratio_tomo_nc4_ppp0.05"]["ours"] == pytest.approx(1.0, rel=1e-12)  # the normalisation
    conv = res["curves"]["lf_image_convergence"]
    e = conv["y"]["rel_l2_vs_monte_carlo"]
    assert all(b < a for a, b in zip(e, e[1:], strict=False))  # more rays, closer to the Monte Carlo image
    for cv in res["curves"].values():
        assert all(len(v) == len(cv["x"]) for v in cv["y"].values())
    assert (tmp_path / "report.md").is_file() and (tmp_path / "fig8_table3.png").is_file()
    # the experiment replica (scenes/lfpiv_tomo_paper): the rendered rig's LTPR is Table 4's, the
    # full-sensor vector count its bookkeeping, the two arms' fields overlap on the lip line
    assert rows["experiment_ltpr"]["ours"] == pytest.approx(6600 * 4400 / (4 * 480 * 320), rel=1e-12)
    assert rows["experiment_ltpr"]["agrees"]
    assert rows["experiment_lf_vectors_full"]["ours"] == "79 x 52 x 19"
    r = rows["experiment_lf_tomo_correlation"]["ours"]
    assert r is not None and -1.0 <= r <= 1.0
    assert rows["experiment_time_ratio_lf_over_tomo"]["ours"] > 0
    assert (tmp_path / "experiment_lf_vs_tomo.png").is_file()
    # the replica's light-field arm drops the field's edge (experiment.toml: min_coverage = 0.75)
    from mitpiv.io.records import read_json

    # experiment runs live under the study's code version (work/runs/<code hash>/)
    runs = {p.name.split("_")[2]: p for p in (tmp_path / "work" / "runs" / res["code_hash"]).glob("experiment_lf_*")}
    assert "mean4" in runs and len(runs) == 2  # Table 4's and the variant
    stage = read_json(next(p for k, p in runs.items() if k != "mean4") / "reconstruct" / "stage.json")
    assert stage["result"]["frame0"]["edge_voxels_dropped"] > 0
    # the variant: the jet's mean flow only, two more passes at the final window
    for arm in ("lf", "tomo"):
        assert rows[f"experiment_mean4_{arm}_outlier_pct"]["ours"] is not None
    exp = read_json(runs["mean4"] / "experiment.json")
    assert exp["flow"]["envelope"] == 0.0 and len(exp["piv"]["windows"]) == 4
    # the ideal-volume diagnostic of the replica: both arms on their own particles, the factor grid
    for arm in ("lf", "tomo"):
        assert rows[f"experiment_{arm}_ideal_rms_vox"]["ours"] > 0
        assert rows[f"experiment_{arm}_particles_per_final_window"]["ours"] > 0
    factors = [r for r in rows if r.startswith("experiment_ideal_seeding_")]
    assert len(factors) == 8 and all(rows[r]["ours"] is not None for r in factors)
    assert (tmp_path / "experiment_ideal_factors.png").is_file()


def test_ideal_piv_recovers_a_uniform_translation_and_counts_the_window():
    """The replica's ideal-volume PIV: a uniform translation (an exact, known answer) comes
    back to a small fraction of a voxel with no outliers, scored by the runner's
    velocity_error; the runner's PIV settings pass through."""
    from mitpiv.grid import VoxelGrid
    from mitpiv.physics.flows import flow_from_dict
    from mitpiv.replications.lfpiv_vs_tomo.study import _ideal_piv

    grid = VoxelGrid.from_bounds([0.0, 0.0, 0.0], [1.6, 1.6, 1.6], 0.025)  # 64^3
    rng = np.random.default_rng(3)
    p0 = rng.random((1500, 3)) * 1.8 - 0.1
    dt = 0.01
    flow = flow_from_dict({"kind": "uniform", "velocity_mm_s": [7.5, -5.0, 2.5]})  # (3, -2, 1) voxels
    p1 = p0 + np.array([7.5, -5.0, 2.5]) * dt
    r = _ideal_piv(p0, p1, grid, flow, dt, {"windows": [32, 16], "overlap": 0.75, "deform": True,
                                            "replace": "median"})
    assert r["outlier_ratio"] < 0.01 and r["n_vectors"] == 13**3  # the UOD flags a few in 10^3 of noise
    assert max(r["rms_vox"]) < 0.05 and max(r["median_abs_vox"]) < 0.05
    with pytest.raises(ConfigError):
        _ideal_piv(p0, p1, grid, flow, dt, {"windows": [32, 16], "overlap": 1.5})


def test_subwindow_motion_of_a_linear_flow_is_all_followed_by_a_deforming_window():
    """Solid-body rotation is linear: nothing is left after the linear fit, and the spread of
    u = -omega y over a window of width W is omega W / sqrt(12) (a uniform distribution) times
    dt over the voxel; a sinusoidal (ABC) flow leaves a non-linear part."""
    from mitpiv.physics.flows import flow_from_dict
    from mitpiv.replications.lfpiv_vs_tomo.study import subwindow_motion

    rot = flow_from_dict({"kind": "solid_body", "omega_rad_s": 2.0, "center": [0, 0, 0], "axis": [0, 0, 1]})
    c = np.random.default_rng(0).random((50, 3)) * 4.0
    m = subwindow_motion(rot, c, [1.0, 0.5, 0.5], 0.01, 0.1, samples=2000)
    assert max(m["nonlinear_vox"]) < 1e-9
    # sample std of 2000 uniform points: ~1.6 % relative; 6 % is > 3 sigma
    assert m["spread_vox"][0] == pytest.approx(2.0 * 0.5 / math.sqrt(12) * 0.1 / 0.01, rel=0.06)
    assert m["spread_vox"][1] == pytest.approx(2.0 * 1.0 / math.sqrt(12) * 0.1 / 0.01, rel=0.06)
    assert m["spread_vox"][2] < 1e-12
    abc = flow_from_dict({"kind": "abc", "length_mm": 1.0, "speed_mm_s": 1.0})
    assert min(subwindow_motion(abc, c, 2.0, 0.01, 0.1)["nonlinear_vox"]) > 0.1


def test_field_correlation_is_the_vector_correlation_on_common_points():
    """The LF-vs-Tomo comparison: the second field interpolated (trilinear: exact for linear
    fields) at the first's valid vectors inside its grid; r = 1 for the same flow sampled on
    two grids, -1 for the reversed fluctuation, and blind to a shared mean vector."""
    from mitpiv.replications.lfpiv_vs_tomo.study import _common_points_correlation

    def field(x, y, z, f, valid=None):
        zz, yy, xx = np.meshgrid(z, y, x, indexing="ij")
        u, v, w = f(xx, yy, zz)
        return {"x_mm": x, "y_mm": y, "z_mm": z, "u": u, "v": v, "w": w,
                "valid": np.ones(u.shape, bool) if valid is None else valid}

    lin = lambda x, y, z: (100 + 3 * x - y, 2 * z + 0.5 * x, -y + z)  # noqa: E731
    a = field(np.linspace(-1, 1, 5), np.linspace(9, 11, 4), np.linspace(-4, 4, 9), lin)
    b = field(np.linspace(-3, 3, 7), np.linspace(7, 13, 8), np.linspace(-5, 5, 11), lin)
    c = _common_points_correlation(a, b)
    assert c["n"] == 5 * 4 * 9 and c["r"] == pytest.approx(1.0, abs=1e-12) and c["rms_diff_mm_s"] < 1e-9
    rev = field(np.linspace(-3, 3, 7), np.linspace(7, 13, 8), np.linspace(-5, 5, 11),
                lambda x, y, z: tuple(50.0 - q for q in lin(x, y, z)))
    assert _common_points_correlation(a, rev)["r"] == pytest.approx(-1.0, abs=1e-12)
    # vectors outside the second grid or invalid are left out
    small = field(np.linspace(-1, 0, 3), np.linspace(9, 11, 4), np.linspace(-4, 4, 9), lin)
    assert _common_points_correlation(a, small)["n"] == 3 * 4 * 9
    a["valid"][0] = False
    assert _common_points_correlation(a, b)["n"] == 5 * 4 * 8


def test_full_scale_estimate_fits_a_night_on_two_cores():
    est = cost_estimate(False)
    assert est["points"] == 12
    assert est["cpu_s"] / 2 < 8 * 3600, est


# ---------------------------------------------------------------------- the paper's equations and tables
def test_ltpr_is_the_papers_ratio():
    # LTPR = (p_x p_y)_LF / (p_x p_y N_c)_Tomo, written afresh; Table 1's six values
    for lf, nc, paper in ((800, 4, 6.25), (800, 6, 4.17), (800, 8, 3.13), (1600, 4, 25.0), (1600, 6, 16.67),
                          (1600, 8, 12.5)):
        ours = S.ltpr((lf, lf), (160, 160), nc)
        assert ours == pytest.approx(lf * lf / (160.0 * 160.0 * nc), rel=1e-15)
        assert ours == pytest.approx(paper, abs=0.005)  # the paper rounds to two decimals
    assert S.ltpr((6600, 4400), (480, 320), 4) == pytest.approx(47.27, abs=0.005)  # Table 4's experiment
    with pytest.raises(ConfigError):
        S.ltpr((800, 800), (160, 160), 0)


@pytest.mark.parametrize("cam,pmr,pl_mm,ppp", [("low", 7, 0.105, 0.0118), ("low", 14, 0.210, 0.0029),
                                               ("low", 28, 0.420, 0.0007), ("high", 7, 0.0525, 0.0118),
                                               ("high", 14, 0.105, 0.0029), ("high", 28, 0.210, 0.0007)])
def test_light_field_cameras_are_table_1(cam, pmr, pl_mm, ppp):
    case = S.LFCase(cam, pmr, 12.0)
    c = S.lf_camera(case)
    assert c.resolution == (S.LF_CAMERAS[cam]["resolution"],) * 2
    assert c.mla_count == S.LF_CAMERAS[cam]["mla"][pmr] and c.mla_layout == "hex"
    assert c.mla_pitch_um * 1e-3 == pytest.approx(pl_mm, rel=1e-12)
    assert c.mla_f_number == pytest.approx(c.image_f_number, rel=1e-12)  # f-number matching
    assert c.gap_mm == pytest.approx(c.mla_focal_length_um * 1e-3, rel=1e-12)  # MLA one focal length from the sensor
    assert c.magnification == pytest.approx(1.0, rel=1e-12)  # p_p is the pixel and the object-space pixel
    # Table 1's ppp: particles per pixel at 0.5 ppm (two significant digits)
    assert case.n_particles() / c.resolution[0] ** 2 == pytest.approx(ppp, abs=0.00006)
    # Table 2's voxels: 2:2:10 of the pixel, the volume 12 x 12 x 10 mm
    vx, vy, vz = case.voxel_mm
    p = S.LF_CAMERAS[cam]["pixel_um"] * 1e-3
    assert (vx, vy, vz) == pytest.approx((2 * p, 2 * p, 10 * p), rel=1e-12)
    g = case.grid()
    assert g.shape == ((67, 400, 400) if cam == "low" else (134, 800, 800))


def test_light_field_point_images_on_the_lenslet_below():
    # a particle on the focal plane sends every ray through the lenslet its image falls on:
    # all light within that lenslet's cell (the aperture image, f-number matched)
    cam = S.lf_camera(S.LFCase("low", 14, 2.4))
    img = S.render_light_field(cam, np.array([[0.0, 0.0, 0.0]]), rays_per_aperture_pixel=4, seed=0)
    k = S.rays_per_particle(cam, 4)
    assert img.sum() == pytest.approx(k, rel=0.05)  # the jittered grid: pi n^2 / 4 rays on average
    v, u = np.nonzero(img)
    span = max(u.max() - u.min(), v.max() - v.min()) + 1
    assert span <= cam.pmr + 1


def test_light_field_image_converges_to_monte_carlo():
    from mitpiv.replications.lfpiv_vs_tomo.study import convergence

    c = convergence({"convergence_random_rays": 400_000, "convergence_levels": (1.0, 4.0, 16.0)}, seed=3)
    e = c["rel_l2"]
    assert e[0] > e[1] > e[2]
    assert e[2] < 0.15  # 16 rays per aperture pixel: within 15 % (L2) of the Monte Carlo image
    assert c["reference_noise"] < 0.05


def test_tomographic_cameras_are_section_2_2():
    # thin lens: 1/85 = 1/93.4 + 1/946.5 (the paper's focal length, image and object distance)
    assert 1 / S.TOMO["image_distance_mm"] + 1 / S.TOMO["object_distance_mm"] == pytest.approx(1 / 85.0, rel=1e-3)
    for nc in (4, 6, 8):
        case = S.TomoCase(nc, 0.05, 12.0)
        cams = S.tomo_cameras(case)
        assert len(cams) == nc
        az = case.azimuths_deg()
        assert np.diff(az) == pytest.approx(np.full(nc - 1, 180.0 / nc))  # distinct directions over 180 deg
        for c in cams:
            assert c.resolution == (160, 160)
            assert abs(c.position_mm[1]) < 1e-12  # the x-z plane
            assert np.linalg.norm(c.position_mm) == pytest.approx(946.5, rel=1e-12)
            # 0.075 mm per pixel at the volume centre, along y (parallel to every image plane)
            uv = c.project(np.array([[0.0, -0.0375, 0.0], [0.0, 0.0375, 0.0]]))
            assert np.linalg.norm(uv[1] - uv[0]) == pytest.approx(1.0, rel=1e-6)
    assert S.TomoCase(4, 0.05, 12.0).n_particles() == 1280 and S.TomoCase(4, 0.1, 12.0).n_particles() == 2560
    assert S.TomoCase(4, 0.05, 12.0).grid().shape == (133, 160, 160)


def test_tomographic_particle_image_is_3px():
    case = S.TomoCase(4, 0.05, 12.0)
    cam = S.tomo_cameras(case)[1]
    o, d = cam.pixel_to_ray(np.array([80.5, 80.5]))
    p = o + d * (946.5 / np.linalg.norm(d))
    img = S.render_tomo([cam], p[None, :])[0]
    assert img.max() == pytest.approx(255.0, rel=1e-6)
    # a Gaussian of e^-2 diameter 3 px (sigma 0.75 px) integrated over pixels: neighbour / centre
    from scipy.special import ndtr

    s = 0.75
    ratio = (ndtr(1.5 / s) - ndtr(0.5 / s)) / (ndtr(0.5 / s) - ndtr(-0.5 / s))
    j, i = np.unravel_index(int(img.argmax()), img.shape)
    assert img[j, i + 1] / img[j, i] == pytest.approx(ratio, rel=2e-3)


def test_window_plan_is_table_2():
    # second windows in mm (Table 2's last row): LF low 1.2, 2.4, 4.8; high 0.6, 1.2, 2.4; Tomo 2.4, 1.2
    for cam, mm in (("low", (1.2, 2.4, 4.8)), ("high", (0.6, 1.2, 2.4))):
        for pmr, want in zip((7, 14, 28), mm, strict=True):
            first, second = S.window_plan("lf", pmr)
            assert first == tuple(2 * v for v in second)
            size = np.asarray(second) * np.asarray(S.LFCase(cam, pmr, 12.0).voxel_mm)
            assert size == pytest.approx([want] * 3, rel=1e-9)
    for ppp, want in ((0.05, 2.4), (0.1, 1.2)):
        _, second = S.window_plan("tomo", ppp)
        assert np.asarray(second) * 0.075 == pytest.approx([want] * 3, rel=1e-9)
    assert S.window_plan("lf", 28, fit_shape_zyx=(67, 100, 100)) == [(100, 100, 64), (100, 100, 32)]


# ---------------------------------------------------------------------- the flow
def test_jet_mean_profile_is_the_published_tanh_with_brown_roshko_spreading():
    jet = NearFieldJet(40.0, 62.5, seed=0)
    x = 40.0
    r = np.linspace(0.0, 40.0, 4001)
    dw = 0.18 * x  # Brown & Roshko (1974): d delta_w / dx = 0.181 for a layer into fluid at rest
    u_ref = 31.25 * (1 + np.tanh(2 * (20.0 - r) / dw))  # Michalke's tanh profile, written afresh
    u = jet.mean_axial(np.full_like(r, x), r)
    assert u == pytest.approx(u_ref, rel=1e-12, abs=1e-12)
    # the vorticity thickness from the profile's steepest slope
    slope = np.max(np.abs(np.gradient(u, r)))
    assert 62.5 / slope == pytest.approx(BROWN_ROSHKO_SPREADING * x, rel=1e-3)


def test_jet_is_divergence_free_and_has_the_mixing_layer_intensity():
    jet = NearFieldJet(40.0, 62.5, nozzle_mm=(-40.0, -20.0, 0.0), seed=1)
    rng = np.random.default_rng(0)
    p = rng.uniform(-6, 6, (40, 3))
    h = 1e-3
    div = sum((jet.velocity(p + h * e)[:, i] - jet.velocity(p - h * e)[:, i]) / (2 * h)
              for i, e in enumerate(np.eye(3)))
    grad_scale = 62.5 / (0.18 * 40.0)  # the mean shear [1/s]
    assert np.max(np.abs(div)) < 1e-4 * grad_scale  # central differences: truncation only
    # r.m.s. on the lip line (eta = 0) over many independent points: the isotropic mean of
    # Bell & Mehta's peaks; sampling tolerance 15 % (large eddies, a few thousand points)
    # points on the lip cylinder r = R (eta = 0: q = q0 and grad q = 0 whatever delta_w), spread
    # along 1-440 mm of the axis and round it so that they sample many independent eddies
    a = rng.uniform(0, 2 * math.pi, 4000)
    ring = np.column_stack([rng.uniform(-39.0, 400.0, 4000), 20 * np.cos(a) - 20.0, 20 * np.sin(a)])
    want = math.sqrt(sum(v * v for v in MIXING_LAYER_RMS) / 3) * 62.5
    u = jet.fluctuation(ring)
    assert np.sqrt(np.mean(u**2)) == pytest.approx(want, rel=0.15)


def test_jet_mode_sums_are_the_fourier_series_written_afresh():
    """The kernel's sums over the modes against the series evaluated point by point in
    float64 with the standard library (theta_n = k_n . (p - nozzle) + phase_n): 1e-12
    relative, summation-order rounding only."""
    jet = NearFieldJet(40.0, 62.5, nozzle_mm=(-40.0, -20.0, 0.0), modes=64, seed=3)
    p = np.random.default_rng(2).uniform(-10, 10, (7, 3))
    le = jet.length_scale_mm
    psi, curl = jet._psi_and_curl(p, le)
    for i, q in enumerate(p):
        want_psi, want_curl = np.zeros(3), np.zeros(3)
        for k in range(jet.modes):
            kv = jet._khat[k] * jet._kmag_le[k] / le
            th = sum(float(kv[j]) * float(q[j] - jet.nozzle_mm[j]) for j in range(3)) + float(jet._phase[k])
            want_curl += jet._amp[k] * math.cos(th)
            want_psi += np.cross(jet._amp[k], kv) / float(kv @ kv) * math.sin(th)
        assert psi[i] == pytest.approx(want_psi, rel=1e-12, abs=1e-12 * np.abs(want_psi).max())
        assert curl[i] == pytest.approx(want_curl, rel=1e-12, abs=1e-12 * np.abs(want_curl).max())


def test_jet_box_average_of_the_mean_flow():
    jet = NearFieldJet(40.0, 62.5, nozzle_mm=(-40.0, -20.0, 0.0), envelope=0.0)
    p = np.array([[0.0, 0.0, 0.0], [1.0, -2.0, 0.5]])
    # a box of vanishing size is the point value; a box along z (the tanh varies along r ~ y
    # here) averages a smooth field: compare with a fine midpoint rule written afresh
    assert jet.box_average(p, (1e-6, 1e-6, 1e-6)) == pytest.approx(jet.velocity(p), rel=1e-9)
    w = np.array([1.2, 1.2, 1.2])
    t = (np.arange(20) + 0.5) / 20 - 0.5
    g = np.stack(np.meshgrid(t, t, t, indexing="ij"), -1).reshape(-1, 3) * w
    ref = np.array([jet.velocity(q + g).mean(axis=0) for q in p])
    assert jet.box_average(p, w, nodes=4) == pytest.approx(ref, rel=2e-3, abs=1e-3)


def test_jet_rebuilds_from_its_dict_and_ltpr_is_in_the_physics_layer():
    from mitpiv.physics.plenoptic import ltpr

    assert ltpr is S.ltpr
    jet = NearFieldJet(40.0, 62.5, nozzle_mm=(-40.0, -20.0, 0.0), modes=64, seed=5)
    d = jet.to_dict()
    assert d.pop("kind") == "near_field_jet"
    p = np.array([[0.0, 0.0, 0.0], [2.0, -3.0, 1.0]])
    assert NearFieldJet(**d)(p) == pytest.approx(jet(p), rel=1e-12)
    with pytest.raises(ConfigError):
        jet(np.array([[-50.0, 0.0, 0.0]]))  # upstream of the nozzle


def test_light_field_crop_keeps_the_optics_and_the_densities():
    full = S.LFCase("low", 14, 12.0)
    strip = S.LFCase("low", 14, 4.8, 12.0)
    assert strip.sensor_wh == (320, 800) and strip.grid().shape == (67, 400, 160)
    assert strip.mla_count == (23, 66)  # lenslets of the crop, the table's 57 x 66 cut to 40 % along x
    a, b = S.lf_camera(full), S.lf_camera(strip)
    for name in ("pixel_pitch_um", "mla_pitch_um", "mla_focal_length_um", "focal_length_mm", "aperture_diameter_mm",
                 "focus_distance_mm", "mla_gap_um"):
        assert getattr(a, name) == getattr(b, name), name
    # the same particles per microlens, hence per volume
    assert strip.n_particles() / (strip.mla_count[0] * strip.mla_count[1]) == pytest.approx(0.5, abs=0.01)


def test_errors_by_depth_partition_the_scored_vectors():
    """piv_errors_by_depth bins exactly piv_errors' vectors: the per-plane counts add up to the
    valid vectors, the count-weighted mean square per plane equals the overall RMS, which is
    piv_errors' own; the gross-error counts are consistent."""
    from mitpiv.analysis.quality import truth_volume

    case = S.LFCase("low", 14, 1.2, 2.4)
    grid = case.grid()
    fl, passes, dt, p0, p1 = S._particle_pair(case, "lf", 14, grid, 5, 0, 1.0)
    va, vb = truth_volume(p0, grid, 1.0), truth_volume(p1, grid, 1.0)
    d = S.piv_errors_by_depth(va, vb, grid, fl, dt, passes, gross_voxels=0.5)
    ref = S.piv_errors(va, vb, grid, fl, dt, passes)
    n = np.array(d["n"])
    assert n.sum() == d["n_vectors"] == ref["n_valid"] > 0
    ms = (np.array(d["rms_vox"]) ** 2 * n[:, None]).sum(0) / n.sum()
    np.testing.assert_allclose(np.sqrt(ms), d["rms_vox_all"], rtol=1e-12)
    np.testing.assert_allclose(d["rms_vox_all"], ref["rms_vox"], rtol=1e-12)
    assert 0 <= d["n_gross_near_focal_plane"] <= min(d["n_gross"], d["n_near_focal_plane"])
    assert d["half_window_mm"] == pytest.approx(0.5 * passes[-1][2] * grid.voxel_mm[2])


# ---------------------------------------------------------------------- row kinds (REPLICATION.md, point 7)
def test_committed_rows_take_the_declared_kinds():
    """The committed full results classified by the study's KINDS (issue 44): every declaration
    matches a row, the arithmetic on the paper's tables is definition, the rows the paper has no
    value for are info, and no physics row is left uncompared or reads a paper result."""

    from mitpiv.replications.frame import classify_rows, tally, unused_kinds
    from mitpiv.replications.lfpiv_vs_tomo.study import INPUTS_FROM_PAPER, KINDS

    rows = committed_rows("lfpiv-vs-tomo")
    out = {r.id: r for r in classify_rows(STUDY, rows)}
    assert STUDY.kinds is KINDS and STUDY.inputs_from_paper is INPUTS_FROM_PAPER
    assert unused_kinds(STUDY, rows) == []
    # arithmetic on the paper's tables: LTPRs, particle and vector counts, the time normalisation
    for rid in ("ltpr_low_nc4", "ltpr_high_nc8", "particles_lf_pmr7_low", "particles_lf_pmr28_low",
                "particles_tomo_ppp0.1", "time_ratio_tomo_nc4_ppp0.05", "experiment_ltpr", "experiment_tomo_vectors",
                "experiment_lf_vectors_full"):
        assert out[rid].kind == "definition", rid
    assert out["experiment_lf_vectors_full"].reads == ("table4_lf_grid",)
    # the crossings are an ordering of simulated errors (they could fail), with the caveat printed
    for nc in (4, 6, 8):
        r = out[f"ltpr_cross_nc{nc}"]
        assert r.kind == "physics" and "ordering" in r.why
    for rid in ("w_rms_px_pmr14_high", "lf_xy_pos_error_high_over_low_pmr7", "experiment_lf_outlier_pct",
                "experiment_lf_tomo_correlation", "time_ratio_lf_pmr14_high"):
        assert out[rid].kind == "physics", rid
    # could not have failed: the tomographic time ratios within a factor 3 of 1.01-1.37
    assert out["time_ratio_tomo_nc8_ppp0.1"].kind == "info"
    # every row the paper has no value for is info (46 in the committed run)
    uncompared = [r.id for r in rows if r.agrees is None]
    assert len(uncompared) == 46 and all(out[i].kind == "info" for i in uncompared)
    assert not [i for i, r in out.items() if r.kind == "physics" and r.agrees is None]
    assert not [i for i, r in out.items() if r.kind == "physics" and r.reads]
    assert all(r.why.strip() for r in out.values() if r.kind != "physics")
    counts = {k: sum(r.kind == k for r in out.values()) for k in ("physics", "input", "definition", "info")}
    assert counts == {"physics": 23, "input": 0, "definition": 18, "info": 52}
    assert tally(list(out.values())) == {"n": 23, "agree": 14, "disagree": 9, "inconclusive": 0}
