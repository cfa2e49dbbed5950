"""Peer trackers' settings derived from a run (issue 52, item 4; mitpiv.studies.peer_settings)
and the exports that use them (mitpiv.studies.export.export_tracker_inputs).

Independent references, computed here in closed form: a synthetic run folder with a known
uniform flow (the motion per frame is ``|U| dt``, its axis components ``|U_i| dt``, no
acceleration), cameras at a known distance looking at the box centre (one pixel there is
``D pitch / f`` in object space), particle images drawn as point-sampled Gaussians of a known
width (whose 3-point logarithmic fit is exact: ``hwhm = sqrt(2 ln 2) sigma``), an OTF file
with a known covariance (its weaker axis from ``numpy.linalg.eigvalsh``) and a known
seeding (``(V / N)^(1/3)``). The written config files are parsed back.
"""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from mitpiv.io import write_exr, write_json, write_truth
from mitpiv.io.openlpt import OpenLPTSettings
from mitpiv.io.openptv import OpenPTVSettings
from mitpiv.physics.camera import PinholeCamera, look_at_rotation
from mitpiv.studies import peer_settings as ps
from mitpiv.studies.export import export_tracker_inputs

HAS_OPENLPT = importlib.util.find_spec("pyopenlpt") is not None

#: The set-up: cameras D mm from the box centre, f mm lenses, pitch um pixels.
D_MM, F_MM, PITCH_UM = 400.0, 50.0, 10.0
RES = (160, 120)
LO, HI = np.array([-3.0, -2.0, -1.0]), np.array([3.0, 2.0, 1.0])
U_MM_S, DT_S = np.array([60.0, -20.0, 10.0]), 0.004  # 0.26 mm (3.2 px) per frame
SIGMA_PX = 0.9
#: Float64 closed forms against float64 code: only rounding differs.
EXACT = 1e-9


def _cameras():
    out = []
    for ax, ay in ((0.45, 0.3), (-0.45, 0.3), (-0.45, -0.3), (0.45, -0.3)):
        d = np.array([ax, ay, 1.0]) / np.linalg.norm([ax, ay, 1.0])
        pos = D_MM * d  # the box centre is the origin
        out.append(PinholeCamera(RES, F_MM, PITCH_UM, rotation=look_at_rotation(pos, np.zeros(3), up=(0.0, 1.0, 0.0)),
                                 position_mm=pos))
    return out


def _blobs(cam, pts, sigma=SIGMA_PX):
    """Point-sampled Gaussians (peak 1) at the projections of ``pts`` (pixel centres at i + 0.5)."""
    w, h = cam.resolution
    uv = cam.project(pts)
    x, y = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    img = np.zeros((h, w))
    for u, v in uv:
        img += np.exp(-((x - u) ** 2 + (y - v) ** 2) / (2 * sigma**2))
    return img.astype(np.float32)


def _positions(n_in=24, frames=6, seed=3):
    """Frames of a uniform flow: ``n_in`` particles well spread in the box at frame 0, plus
    one outside the box and one absent from frame 0 (neither counts in the seeding)."""
    rng = np.random.default_rng(seed)
    cams = _cameras()
    p0 = []
    for _ in range(5000):  # images at least 8 px apart in every camera: isolated
        p = rng.uniform(LO + 0.3, HI - 0.3)
        if all(np.min(np.linalg.norm(c.project(np.array(p0)) - c.project(p[None]), axis=1)) > 8 for c in cams) \
                if p0 else True:
            p0.append(p)
        if len(p0) == n_in:
            break
    p0 = np.array(p0 + [[5.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    pos = np.stack([p0 + U_MM_S * DT_S * k for k in range(frames)])
    pos[0, -1] = np.nan
    return pos


def _run(folder: Path, *, frames=6, tracking: dict | None = None) -> Path:
    """A run folder reduced to what the derivation reads: experiment.json, the truth and
    the rendered frames with their cameras in the metadata."""
    folder.mkdir(parents=True)
    exp = {"kind": "tracking" if tracking else "tomo",
           "seeding": {"box_min_mm": LO.tolist(), "box_max_mm": HI.tolist()}}
    if tracking:
        exp["tracking"] = tracking
    write_json(folder / "experiment.json", exp)
    pos = _positions(frames=frames)
    stage = "field" if tracking else "particles"
    write_truth(folder / stage / "truth.npz", positions_mm=pos, times_s=DT_S * np.arange(frames),
                diameters_um=np.ones(pos.shape[1]))
    (folder / "render").mkdir()
    for k, cam in enumerate(_cameras()):
        for f in range(frames):
            write_exr(folder / "render" / f"cam{k}_frame{f:03d}.exr", _blobs(cam, pos[f][np.isfinite(pos[f, :, 0])]),
                      {"camera": cam.to_dict(), "sensor_id": f"cam{k}"})
    (folder / "render" / "stage.json").write_text("{}")
    return folder


def _vox():
    return D_MM * PITCH_UM * 1e-3 / F_MM  # mm per px on the optical axis at distance D


def _motion():
    return float(np.linalg.norm(U_MM_S) * DT_S)


def _tracer(path: Path) -> list[float]:
    """The numbers of OpenLPT's tracerConfig.txt, in order (comment lines dropped)."""
    vals = []
    for line in path.read_text().splitlines():
        line = line.split("#")[0].strip()
        if line:
            vals.append(float(line))
    return vals


def test_quantities_of_a_known_uniform_flow(tmp_path):
    q = ps.run_quantities(_run(tmp_path / "run"))
    assert q.voxel_mm == pytest.approx(_vox(), rel=EXACT)
    assert q.motion_mm == pytest.approx(_motion(), rel=EXACT)
    assert q.motion_vox == pytest.approx(_motion() / _vox(), rel=EXACT)
    assert q.motion_axis_mm == pytest.approx(tuple(np.abs(U_MM_S) * DT_S), rel=EXACT)
    assert q.acceleration_mm == pytest.approx(0.0, abs=1e-12)
    # 24 particles in the box at frame 0 (one outside, one absent)
    assert q.n_particles == 24
    assert q.spacing_mm == pytest.approx((np.prod(HI - LO) / 24) ** (1 / 3), rel=EXACT)
    # no OTF: measured on the images, exact for point-sampled Gaussians
    assert q.particle_hwhm_px == pytest.approx(np.sqrt(2 * np.log(2)) * SIGMA_PX, rel=1e-6)
    assert q.particle_radius_px == 1.5  # 1.06 px rounded up to a half pixel
    assert "frame 0's images" in q.sources["particle_hwhm_px"]
    assert q.calibration_error_px == 0.0 and "exact" in q.sources["calibration_error_px"]
    # a tomo run has no [tracking] table: the tracking kind's defaults, said so
    assert (q.tolerance_px, q.search_px) == (ps.DEFAULT_TOLERANCE_PX, ps.DEFAULT_SEARCH_PX)
    assert "defaults" in q.sources["tolerance_px"]
    assert q.pixel_pitch_mm == pytest.approx(PITCH_UM * 1e-3)


def test_the_otf_calibration_and_the_calibrate_stage_are_used_when_the_run_has_them(tmp_path):
    run = _run(tmp_path / "run", tracking={"tolerance_px": 0.8, "search_px": 2.5, "min_intensity": 0.2})
    cov = [(1.6, 0.3, 1.2), (2.0, -0.1, 1.9)]  # (a, b, c) per camera [1/px^2]
    write_json(run / "otf" / "otf.json", {k: [[[[c[i]]]] for c in cov] for i, k in
                                          enumerate(("a_per_px2", "b_per_px2", "c_per_px2"))})
    cams = _cameras()
    write_json(run / "calibrate" / "cameras.json", {"cameras": [c.to_dict() for c in cams],
                                                    "true": [c.to_dict() for c in cams],
                                                    "fit": [{"rms_px": 0.1}, {"rms_px": 0.3}, None, {"rms_px": 0.2}]})
    lam = min(np.linalg.eigvalsh([[a, b], [b, c]])[0] for a, b, c in cov)
    hwhm = np.sqrt(2 * np.log(2) / lam)
    q = ps.run_quantities(run, calibrated=True)
    assert q.particle_hwhm_px == pytest.approx(hwhm, rel=EXACT) and "otf" in q.sources["particle_hwhm_px"]
    assert q.particle_radius_px == np.ceil(2 * hwhm) / 2 == 1.5
    assert q.calibration_error_px == 0.3
    assert (q.tolerance_px, q.search_px, q.ghost_threshold) == (0.8, 2.5, 0.2)
    s = ps.openlpt_settings_from(q)
    assert s.tolerance_2d_px == pytest.approx(0.8 + 3 * 0.3) and s.tolerance_3d_vox == pytest.approx(0.85)
    assert s.ghost_threshold == 0.2
    # the rendered cameras (what the export writes) are exact whatever the calibrate stage fitted
    q2 = ps.run_quantities(run)
    assert q2.calibration_error_px == 0.0 and "0.3 px" in q2.sources["calibration_error_px"]


def test_the_openlpt_export_writes_the_derived_settings(tmp_path):
    run = _run(tmp_path / "run")
    m = export_tracker_inputs(run, tmp_path / "lpt", tool="openlpt")
    v = _tracer(tmp_path / "lpt" / "tracerConfig.txt")
    cover = _motion() / _vox() + ps.DEFAULT_SEARCH_PX
    assert v[0] == pytest.approx(cover, abs=1e-3)  # search radius [voxel]
    assert v[2] == pytest.approx((np.prod(HI - LO) / 24) ** (1 / 3) / _vox(), abs=1e-3)  # neighbour spacing
    assert v[7] == pytest.approx(1.5 * cover, abs=2e-3)  # predictive-field search radius
    assert v[11:13] == [ps.DEFAULT_TOLERANCE_PX, ps.DEFAULT_TOLERANCE_PX / 2]  # 2-D [px], 3-D [voxel]
    assert v[-1] == 1.5  # particle radius [px]
    lines = [x for x in (tmp_path / "lpt" / "config.txt").read_text().splitlines() if not x.startswith("#")]
    assert float(lines[13]) == pytest.approx(_vox(), rel=EXACT)  # the voxel line
    written = json.loads((tmp_path / "lpt" / "mitpiv_export.json").read_text())
    assert written["settings_from"] == m["settings_from"] == "derived"
    d = written["derived_settings"]
    assert d["motion_mm"] == pytest.approx(_motion(), rel=EXACT) and d["voxel_mm"] == pytest.approx(_vox())
    assert "percentile" in d["sources"]["motion_mm"] and d["rules"]["search_radius_vox"]
    assert d["applied"] == {"settings": "derived", "voxel_mm": "derived"}


def test_the_openptv_export_writes_the_derived_settings(tmp_path):
    run = _run(tmp_path / "run")
    export_tracker_inputs(run, tmp_path / "ptv", tool="openptv")
    par = tmp_path / "ptv" / "parameters"
    tr = [float(x) for x in (par / "track.par").read_text().split()]
    margin = ps.DEFAULT_SEARCH_PX * _vox()
    dv = np.abs(U_MM_S) * DT_S + margin
    assert tr[:6] == pytest.approx([-dv[0], dv[0], -dv[1], dv[1], -dv[2], dv[2]], abs=1e-6)
    assert tr[7] == pytest.approx(np.sqrt(6) * 0.5 * ps.DEFAULT_TOLERANCE_PX * _vox(), abs=1e-6)  # dacc [mm]
    eps0 = float((par / "criteria.par").read_text().split()[-1])
    assert eps0 == pytest.approx(ps.DEFAULT_TOLERANCE_PX * PITCH_UM * 1e-3)
    m = json.loads((tmp_path / "ptv" / "mitpiv_export.json").read_text())
    assert m["settings_from"] == "derived" and m["settings"]["max_displacement_mm"] == pytest.approx(list(dv))


def test_explicit_settings_win(tmp_path):
    run = _run(tmp_path / "run")
    m = export_tracker_inputs(run, tmp_path / "a", tool="openlpt", settings=OpenLPTSettings(search_radius_vox=3.25),
                              voxel_mm=0.05)
    assert _tracer(tmp_path / "a" / "tracerConfig.txt")[0] == 3.25 and m["voxel_mm"] == 0.05
    assert m["settings_from"] == "given" and "derived_settings" not in m
    # a given voxel alone: the derived lengths follow it
    m = export_tracker_inputs(run, tmp_path / "b", tool="openlpt", voxel_mm=0.05)
    assert _tracer(tmp_path / "b" / "tracerConfig.txt")[0] == pytest.approx(_motion() / 0.05 + ps.DEFAULT_SEARCH_PX,
                                                                            abs=1e-3)
    assert m["settings_from"] == "derived (voxel_mm given)"
    m = export_tracker_inputs(run, tmp_path / "c", tool="openptv", settings=OpenPTVSettings(max_displacement_mm=0.7))
    tr = [float(x) for x in (tmp_path / "c" / "parameters" / "track.par").read_text().split()]
    assert tr[:6] == [-0.7, 0.7, -0.7, 0.7, -0.7, 0.7] and m["settings_from"] == "given"


def test_the_export_command_says_which_settings(tmp_path, capsys):
    from mitpiv.cli import main

    run = _run(tmp_path / "run", frames=2)
    assert main(["export", str(run), "--openlpt", str(tmp_path / "lpt")]) == 0
    assert "settings derived from the run" in capsys.readouterr().out


@pytest.mark.skipif(not HAS_OPENLPT, reason="OpenLPT (pyopenlpt) is not installed")
def test_openlpt_tracks_the_flow_with_the_derived_settings(tmp_path):
    """OpenLPT itself on the synthetic run (about 24 particles in the box, 8 frames; a
    particle counts as found within 1 px, the tracking kind's ``[evaluate] radius_px``): with
    the derived settings it finds 0.71 of them (so few particles give its predictive field
    little to work with), with its sample settings on the default voxel (the box / 1000: a
    0.06 mm search radius against 0.26 mm of motion per frame) 0.42 (openlpt 2.2.4)."""
    from mitpiv.tracking.peers import run_openlpt

    frames = 8
    run = _run(tmp_path / "run", frames=frames)
    pos = _positions(frames=frames)

    def found(out, **kw):
        export_tracker_inputs(run, out, tool="openlpt", **kw)
        tracks, _ = run_openlpt(out, timeout_s=60)
        hit = 0
        for f in range(frames):
            p = tracks.positions_mm[:, f]
            p = p[np.all(np.isfinite(p), axis=1)]
            for t in pos[f][np.all((pos[f] >= LO) & (pos[f] <= HI), axis=1)]:
                hit += bool(p.size) and np.min(np.linalg.norm(p - t, axis=1)) < _vox()
        inside = sum(np.all((pos[f] >= LO) & (pos[f] <= HI), axis=1).sum() for f in range(frames))
        return hit / inside

    derived = found(tmp_path / "new")
    generic = found(tmp_path / "old", settings=OpenLPTSettings(), voxel_mm=float(np.max(HI - LO) / 1000))
    assert derived > 0.6 and generic < 0.5


def test_a_run_without_a_truth_exports_with_the_defaults_and_says_why(tmp_path):
    import shutil

    from mitpiv.errors import MitpivWarning

    run = _run(tmp_path / "run", frames=2)
    shutil.rmtree(run / "particles")
    with pytest.warns(MitpivWarning, match="no truth"):
        m = export_tracker_inputs(run, tmp_path / "lpt", tool="openlpt")
    assert m["settings_from"] == "defaults" and "no truth" in m["derived_settings"]["error"]
    assert _tracer(tmp_path / "lpt" / "tracerConfig.txt")[0] == OpenLPTSettings().search_radius_vox
