"""Exports to other trackers (issue 27, item 6): OpenLPT's camera files and config, and
OpenPTV's ``.ori`` / ``.addpar`` and parameter folder.

Independent references: each written calibration is read back by a parser written afresh
here from the formats' documentation (OpenLPT's ``Camera.cpp`` loader: comment lines
dropped, comma-separated rows; liboptv's ``read_ori``: whitespace-separated numbers, the
rotation rebuilt from the angles), and known 3-D points are projected with the peer's own
convention written afresh in float64 (OpenLPT: OpenCV's pinhole with rational distortion,
pixel centres on integers; OpenPTV: ``dm^T (p - x0)``, ``x = -cc X / Z``, Brown distortion
from the sensor centre, ``x_pix = x / pitch + W / 2``, ``y_pix = H / 2 - y / pitch``, pixel
``i`` spanning ``[i, i + 1)`` as in mitpiv), then
compared with mitpiv's :meth:`PinholeCamera.project`. Where the peer's package imports
(``pyopenlpt``, ``optv``: the optional ``peers`` extra), its own reader and projection are
compared too.
"""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from mitpiv.errors import ConfigError, FileFormatError
from mitpiv.io import write_exr, write_json, write_truth
from mitpiv.io.openlpt import (
    OpenLPTSettings,
    export_openlpt,
    openlpt_distortion,
    read_openlpt_tracks,
    write_openlpt_camera,
)
from mitpiv.io.openptv import (
    MAX_FIT_PX,
    OpenPTVSettings,
    export_openptv,
    openptv_calibration,
    write_openptv_calibration,
)
from mitpiv.io.tiff import quantise
from mitpiv.physics.camera import PinholeCamera, look_at_rotation
from mitpiv.physics.distortion import Distortion
from mitpiv.physics.plenoptic import PlenopticCamera

#: Pinhole projections through the written files against mitpiv's: both float64, the files
#: carry 17 significant digits; the brief's bound for an exact conversion.
EXACT_PX = 1e-6

HAS_OPENLPT = importlib.util.find_spec("pyopenlpt") is not None
HAS_OPTV = importlib.util.find_spec("optv") is not None

LENSES = {
    "none": Distortion(),
    "barrel": Distortion(k1=-0.08, k2=-0.01),  # no positive term: OpenLPT's rational form
    "pincushion_tangential": Distortion(k1=0.05, k2=-0.02, k3=0.01, p1=2e-3, p2=-1e-3),
}


def _cameras(distortion=Distortion(), *, principal_point_px=None, resolution=(160, 120)):
    """Four cameras around the z axis looking at the origin (a tomo / LPT arrangement)."""
    out = []
    for sx, sy in ((1, 1), (-1, 1), (-1, -1), (1, -1)):
        pos = np.array([120.0 * sx, 90.0 * sy, 400.0])
        rot = look_at_rotation(pos, np.zeros(3), up=(0.0, 1.0, 0.0))
        out.append(PinholeCamera(resolution, 50.0, 10.0, rotation=rot, position_mm=pos, distortion=distortion,
                                 principal_point_px=principal_point_px))
    return out


def _points(n=200, seed=0):
    return np.random.default_rng(seed).uniform([-4, -3, -3], [4, 3, 3], (n, 3))


def _files(folder: Path) -> list:
    return sorted(p for p in folder.rglob("*")) if folder.exists() else []


# ---------------------------------------------------------------------- OpenLPT, read afresh
def _read_openlpt_camera(path):
    """OpenLPT's PINHOLE file as its loader reads it: comment lines dropped, then the model
    name, two error fields, ``n_row,n_col``, 3 rows of K, the distortion row, the Rodrigues
    vector, 3 rows of R, 3 rows of R^-1, T, and -R^-1 T."""
    rows = [ln.split("#")[0].strip() for ln in Path(path).read_text().splitlines()]
    rows = [r for r in rows if r]
    assert rows[0] == "PINHOLE"
    num = [np.array([float(x) for x in r.split(",")]) for r in rows[3:]]
    n_row, n_col = (int(v) for v in num[0])
    return {"n_row": n_row, "n_col": n_col, "K": np.stack(num[1:4]), "dist": num[4], "rvec": num[5],
            "R": np.stack(num[6:9]), "R_inv": np.stack(num[9:12]), "T": num[12], "T_inv": num[13]}


def _openlpt_project(cam, p):
    """OpenCV's pinhole with OpenLPT's distortion terms (k1 k2 p1 p2 [k3 [k4 k5 k6]])."""
    pc = p @ cam["R"].T + cam["T"]
    x, y = pc[:, 0] / pc[:, 2], pc[:, 1] / pc[:, 2]
    d = np.zeros(8)
    d[:len(cam["dist"])] = cam["dist"]
    r2 = x * x + y * y
    radial = (1 + d[0] * r2 + d[1] * r2**2 + d[4] * r2**3) / (1 + d[5] * r2 + d[6] * r2**2 + d[7] * r2**3)
    xd = x * radial + 2 * d[2] * x * y + d[3] * (r2 + 2 * x * x)
    yd = y * radial + d[2] * (r2 + 2 * y * y) + 2 * d[3] * x * y
    K = cam["K"]
    return np.stack([K[0, 0] * xd + K[0, 2], K[1, 1] * yd + K[1, 2]], axis=1)


@pytest.mark.parametrize("lens", sorted(LENSES))
def test_openlpt_camera_file_projects_like_mitpiv(lens, tmp_path):
    p = _points()
    for k, cam in enumerate(_cameras(LENSES[lens], principal_point_px=(83.25, 57.5))):
        f = write_openlpt_camera(tmp_path / f"cam{k}.txt", cam)
        c = _read_openlpt_camera(f)
        assert (c["n_row"], c["n_col"]) == (120, 160)
        assert np.allclose(c["R"] @ c["R_inv"], np.eye(3), atol=1e-14)
        assert np.allclose(cv2.Rodrigues(c["rvec"])[0], c["R"], atol=1e-12)
        assert np.allclose(c["T_inv"], cam.position_mm, atol=1e-12)
        uv_peer = _openlpt_project(c, p)
        # OpenLPT's pixel centres are on integers, mitpiv's at i + 0.5
        assert np.max(np.abs(uv_peer - (cam.project(p) - 0.5))) < EXACT_PX
        if lens == "barrel":  # written in the rational form so that openlpt 2.2.4 applies it
            assert len(c["dist"]) == 8 and c["dist"][5] > 0
        if HAS_OPENLPT:
            import pyopenlpt

            peer = pyopenlpt.Camera(str(f))
            assert peer._pinhole_param.is_distorted == (lens != "none")
            uv = np.array([peer.project(pyopenlpt.Pt3D(*q)).to_list() for q in p])[:, :, 0]
            assert np.max(np.abs(uv - (cam.project(p) - 0.5))) < EXACT_PX


def test_openlpt_distortion_forms():
    """OpenCV order for a lens with a positive term; the rational form is the same model."""
    assert openlpt_distortion(Distortion(k1=0.1, p1=0.01)) == [0.1, 0.0, 0.01, 0.0, 0.0]
    d = openlpt_distortion(Distortion(k1=-0.2, k2=-0.05))
    r2 = np.linspace(0, 0.3, 7)
    assert np.allclose((1 + d[0] * r2 + d[1] * r2**2 + d[4] * r2**3) / (1 + d[5] * r2),
                       1 - 0.2 * r2 - 0.05 * r2**2, rtol=0, atol=1e-15)
    with pytest.raises(ConfigError, match="k3 != 0"):
        openlpt_distortion(Distortion(k1=-0.1, k3=-0.01))


def _read_config(path):
    rows = [ln.strip() for ln in Path(path).read_text().splitlines()]
    return [r for r in rows if r and not r.startswith("#")]


def test_export_openlpt_folder(tmp_path):
    cams = _cameras(LENSES["barrel"])
    rng = np.random.default_rng(3)
    frames = [[rng.random((120, 160)) * (k + 1) for _ in range(3)] for k in range(4)]
    m = export_openlpt(tmp_path / "lpt", frames, cams, lower_mm=[-5, -4, -3], upper_mm=[5, 4, 3], frame_rate_hz=500.0,
                       settings=OpenLPTSettings(search_radius_vox=12.0))
    cfg = _read_config(tmp_path / "lpt" / "config.txt")
    assert cfg[0] == "0,2" and float(cfg[1]) == 500.0 and cfg[3] == "4"
    cam_files = [r.split(",") for r in cfg[4:8]]
    assert all(int(top) == 255 and (tmp_path / "lpt" / name).is_file() for name, top in cam_files)
    lists = [tmp_path / "lpt" / r for r in cfg[8:12]]
    assert [float(v) for v in cfg[12].split(",")] == [-5, 5, -4, 4, -3, 3]
    assert float(cfg[13]) == pytest.approx(0.01)  # largest side / 1000
    assert cfg[15] == "Tracer" and (tmp_path / "lpt" / cfg[16]).is_file()
    assert _read_config(tmp_path / "lpt" / cfg[16])[0].startswith("12 ")
    # one gain for all: 255 / the brightest pixel of all cameras and frames
    gain = 255 / max(f.max() for cam in frames for f in cam)
    assert m["gain"] == pytest.approx(gain, rel=1e-12)
    for k, lst in enumerate(lists):
        names = lst.read_text().split()
        assert len(names) == 3
        for f, name in enumerate(names):
            img = cv2.imread(str(tmp_path / "lpt" / name), cv2.IMREAD_UNCHANGED)
            assert img.dtype == np.uint8 and img.shape == (120, 160)
            assert np.array_equal(img, np.clip(np.rint(frames[k][f] * gain), 0, 255).astype(np.uint8))
    assert json.loads((tmp_path / "lpt" / "mitpiv_export.json").read_text())["n_frames"] == 3


def test_export_openlpt_16_bit(tmp_path):
    cams = _cameras()[:2]
    frames = [[np.full((120, 160), 2.0)], [np.full((120, 160), 4.0)]]
    m = export_openlpt(tmp_path / "lpt", frames, cams, lower_mm=[-1] * 3, upper_mm=[1] * 3, bits=16, gain=1000.0)
    img = cv2.imread(str(tmp_path / "lpt" / "imgFile/cam2/img00000.tif"), cv2.IMREAD_UNCHANGED)
    assert img.dtype == np.uint16 and np.all(img == 4000) and m["gain"] == 1000.0
    assert _read_config(tmp_path / "lpt" / "config.txt")[4].endswith(",65535")
    assert np.array_equal(quantise(np.array([-1.0, 0.4, 70000.0]), 1.0, 16), [0, 0, 65535])


@pytest.mark.parametrize("case", ["no_frames", "plenoptic", "barrel_k3", "frame_size", "box"])
def test_export_openlpt_bad_inputs_write_nothing(case, tmp_path):
    cams = _cameras()
    frames = [[np.ones((120, 160))] for _ in cams]
    kw = {"lower_mm": [-1] * 3, "upper_mm": [1] * 3}
    match = {"no_frames": "without rendered images", "plenoptic": "PlenopticCamera", "barrel_k3": "k3 != 0",
             "frame_size": "resolution", "box": "lower_mm"}[case]
    if case == "no_frames":
        frames = [[] for _ in cams]
    elif case == "plenoptic":
        cams[1] = PlenopticCamera((160, 120), pixel_pitch_um=5.0, focal_length_mm=50.0, f_number=4.0,
                                  focus_distance_mm=250.0, mla_pitch_um=25.0)
    elif case == "barrel_k3":
        cams = _cameras(Distortion(k1=-0.1, k3=-0.02))
    elif case == "frame_size":
        frames[2] = [np.ones((100, 160))]
    else:
        kw["upper_mm"] = [1, -2, 1]
    with pytest.raises(ConfigError, match=match):
        export_openlpt(tmp_path / "out", frames, cams, **kw)
    assert _files(tmp_path / "out") == []


def test_read_openlpt_tracks(tmp_path):
    """The CSV layout openlpt 2.2.4 writes (header as in its ConvergeTrack files)."""
    head = "TrackID,FrameID,WorldX,WorldY,WorldZ,cam0_x(col),cam0_y(row)\n"
    (tmp_path / "LongTrackActive_4.csv").write_text(head + "0,1,1.0,2.0,3.0,5,5\n0,2,1.5,2.0,3.0,6,5\n"
                                                    "3,0,-1.0,0.0,0.0,1,1\n")
    (tmp_path / "ExitTrack_4.csv").write_text(head + "0,3,9.0,9.0,9.0,1,1\n")
    r = read_openlpt_tracks(tmp_path, n_frames=5)
    pos = r["positions_mm"]
    assert pos.shape == (3, 5, 3)  # track 0 of each file stays its own track
    assert np.isfinite(pos[..., 0]).sum() == 4
    assert any(np.array_equal(t[1:3], [[1, 2, 3], [1.5, 2, 3]]) for t in pos)
    with pytest.raises(FileFormatError, match="outside"):
        read_openlpt_tracks(tmp_path, n_frames=3)
    (tmp_path / "bad.csv").write_text("a,b\n1,2\n")
    with pytest.raises(FileFormatError, match="OpenLPT track file"):
        read_openlpt_tracks(tmp_path)


# ---------------------------------------------------------------------- OpenPTV, read afresh
def _read_ori(ori, addpar):
    """liboptv's read_ori: x0 y0 z0 omega phi kappa, a 3 x 3 matrix (ignored: rebuilt from
    the angles), xh yh cc, the glass vector; addpar k1 k2 k3 p1 p2 scx she."""
    v = [float(x) for x in Path(ori).read_text().split()]
    a = [float(x) for x in Path(addpar).read_text().split()]
    return {"x0": np.array(v[0:3]), "angles": v[3:6], "dm_file": np.array(v[6:15]).reshape(3, 3),
            "xh": v[15], "yh": v[16], "cc": v[17], "glass": np.array(v[18:21]), "ap": a}


def _ptv_rotation(omega, phi, kappa):
    co, so, cp, sp, ck, sk = np.cos(omega), np.sin(omega), np.cos(phi), np.sin(phi), np.cos(kappa), np.sin(kappa)
    return np.array([[cp * ck, -cp * sk, sp], [co * sk + so * sp * ck, co * ck - so * sp * sk, -so * cp],
                     [so * sk - co * sp * ck, so * ck + co * sp * sk, co * cp]])


def _openptv_project(cal, p, imx, imy, pitch):
    dm = _ptv_rotation(*cal["angles"])
    q = (p - cal["x0"]) @ dm  # dm^T (p - x0) per point
    x = -cal["cc"] * q[:, 0] / q[:, 2] + cal["xh"]
    y = -cal["cc"] * q[:, 1] / q[:, 2] + cal["yh"]
    k1, k2, k3, p1, p2, scx, she = cal["ap"]
    r2 = x * x + y * y
    rad = 1 + k1 * r2 + k2 * r2**2 + k3 * r2**3
    xd = x * rad + p1 * (r2 + 2 * x * x) + 2 * p2 * x * y
    yd = y * rad + p2 * (r2 + 2 * y * y) + 2 * p1 * x * y
    xd, yd = scx * (xd - np.sin(she) * yd), scx * np.cos(she) * yd
    return np.stack([xd / pitch + imx / 2, imy / 2 - yd / pitch], axis=1)


@pytest.mark.parametrize("lens,centred", [("none", False), ("pincushion_tangential", True), ("barrel", False)])
def test_openptv_calibration_projects_like_mitpiv(lens, centred, tmp_path):
    p = _points(seed=1)
    # OpenPTV centres distortion on the sensor centre (W/2, H/2), mitpiv's default principal point
    pp = None if centred else (83.25, 57.5)
    for k, cam in enumerate(_cameras(LENSES[lens], principal_point_px=pp)):
        info = write_openptv_calibration(tmp_path / f"cam{k}.tif.ori", cam)
        cal = _read_ori(tmp_path / f"cam{k}.tif.ori", tmp_path / f"cam{k}.tif.addpar")
        assert np.allclose(_ptv_rotation(*cal["angles"]), cal["dm_file"], atol=1e-14)
        assert np.linalg.norm(cal["glass"]) > 0
        uv = _openptv_project(cal, p, 160, 120, 0.01)
        err = np.max(np.abs(uv - cam.project(p)))  # the same pixel convention
        expected = {"none": "none", "pincushion_tangential": "exact", "barrel": "fitted"}[lens]
        assert info["distortion"] == expected
        # fitted: OpenPTV centres distortion on the sensor, mitpiv on the principal point
        # (3.6 px apart here); the fit's own worst case on the sensor bounds the difference
        tol = EXACT_PX if expected != "fitted" else info["distortion_fit_px"] + 1e-9
        assert err < tol
        if expected == "fitted":
            assert 0 < info["distortion_fit_px"] < MAX_FIT_PX
        if HAS_OPTV:
            from optv.calibration import Calibration
            from optv.imgcoord import image_coordinates
            from optv.parameters import ControlParams, MultimediaParams
            from optv.transforms import convert_arr_metric_to_pixel

            c = Calibration()
            c.from_file(str(tmp_path / f"cam{k}.tif.ori").encode(), str(tmp_path / f"cam{k}.tif.addpar").encode())
            cpar = ControlParams(1, image_size=(160, 120), pixel_size=(0.01, 0.01))
            xy = convert_arr_metric_to_pixel(image_coordinates(p, c, MultimediaParams(n1=1.0, n2=[1.0], n3=1.0,
                                                                                     d=[1.0])), cpar)
            assert np.max(np.abs(xy - cam.project(p))) < tol


def test_openptv_distortion_fit_off_centre():
    """A 3 % barrel (k1 = -0.03 / r_corner^2, r_corner = 0.02): half a pixel off OpenPTV's
    centre the fit stays far inside the limit; 20 px off it cannot, and the export is refused."""
    lens = Distortion(k1=-75.0)
    assert openptv_calibration(_cameras(lens, principal_point_px=(80.5, 60.5))[0])["distortion_fit_px"] < 1e-3
    with pytest.raises(ConfigError, match="sensor centre"):
        openptv_calibration(_cameras(lens, principal_point_px=(60.0, 40.0))[0])


def test_export_openptv_folder(tmp_path):
    cams = _cameras(LENSES["barrel"])
    rng = np.random.default_rng(4)
    frames = [[rng.random((120, 160)) for _ in range(2)] for _ in cams]
    m = export_openptv(tmp_path / "ptv", frames, cams, lower_mm=[-5, -4, -3], upper_mm=[5, 4, 3], first_frame=10001)
    par = tmp_path / "ptv" / "parameters"
    ptv = (par / "ptv.par").read_text().split()
    assert ptv[0] == "4" and ptv[1:3] == ["img/cam1.10001", "cal/cam1.tif"]
    assert [int(v) for v in ptv[12:14]] == [160, 120] and [float(v) for v in ptv[14:16]] == [0.01, 0.01]
    assert [float(v) for v in ptv[17:20]] == [1.0, 1.0, 1.0]  # air everywhere
    seq = (par / "sequence.par").read_text().split()
    assert seq == ["img/cam1.", "img/cam2.", "img/cam3.", "img/cam4.", "10001", "10002"]
    crit = [float(v) for v in (par / "criteria.par").read_text().split()]
    assert crit[:6] == [-5, -3, 3, 5, -3, 3]
    for k in range(4):
        for f in range(2):
            img = cv2.imread(str(tmp_path / "ptv" / "img" / f"cam{k + 1}.{10001 + f}"), cv2.IMREAD_UNCHANGED)
            assert np.array_equal(img, quantise(frames[k][f], m["gain"], 8))
        assert (tmp_path / "ptv" / "cal" / f"cam{k + 1}.tif.addpar").is_file()
    assert len((tmp_path / "ptv" / "cal" / "target.txt").read_text().splitlines()) == 8
    if HAS_OPTV:
        from optv.parameters import ControlParams, SequenceParams, TargetParams, TrackingParams, VolumeParams

        cp = ControlParams(4)
        cp.read_control_par(str(par / "ptv.par"))
        assert cp.get_image_size() == (160, 120)
        vp = VolumeParams()
        vp.read_volume_par(str(par / "criteria.par"))
        tp = TrackingParams()
        tp.read_track_par(str(par / "track.par"))
        sp = SequenceParams(num_cams=4)
        sp.read_sequence_par(str(par / "sequence.par"), 4)
        tg = TargetParams()
        tg.read(str(par / "targ_rec.par"))
        assert (sp.get_first(), sp.get_last()) == (10001, 10002) and tp.get_dvxmax() == pytest.approx(0.6)
        assert list(tg.get_grey_thresholds()) == [30] * 4


@pytest.mark.parametrize("case", ["sizes", "plenoptic", "no_frames"])
def test_export_openptv_bad_inputs_write_nothing(case, tmp_path):
    cams = _cameras()
    frames = [[np.ones((120, 160))] for _ in cams]
    match = {"sizes": "one image size", "plenoptic": "PlenopticCamera", "no_frames": "without rendered images"}[case]
    if case == "sizes":
        cams[3] = _cameras(resolution=(200, 120))[3]
    elif case == "plenoptic":
        cams[0] = PlenopticCamera((160, 120), pixel_pitch_um=10.0, focal_length_mm=50.0, f_number=4.0,
                                  focus_distance_mm=250.0, mla_pitch_um=50.0)
    else:
        frames = [[] for _ in cams]
    with pytest.raises(ConfigError, match=match):
        export_openptv(tmp_path / "out", frames, cams, lower_mm=[-1] * 3, upper_mm=[1] * 3)
    assert _files(tmp_path / "out") == []


# ---------------------------------------------------------------------- a run folder and the CLI
def _fake_run(folder: Path, *, images: bool = True) -> Path:
    """A run folder as 'mitpiv run' leaves it, reduced to what the export reads: the
    experiment record, the truth's frame times and the render stage's EXR frames with
    their cameras in the metadata."""
    folder.mkdir(parents=True)
    write_json(folder / "experiment.json", {"kind": "tomo", "seeding": {"box_min_mm": [-3, -2, -1],
                                                                          "box_max_mm": [3, 2, 1]}})
    p = _points(20)
    write_truth(folder / "particles" / "truth.npz", positions_mm=[p, p + 0.01], times_s=[0.0, 0.002],
                diameters_um=np.ones(20))
    if images:
        (folder / "render").mkdir()
        for k, cam in enumerate(_cameras()):
            for f in (0, 1):
                write_exr(folder / "render" / f"cam{k}_frame{f:03d}.exr",
                          np.full((120, 160), 0.5 + k + f, np.float32), {"camera": cam.to_dict(), "sensor_id": f"cam{k}"})
        (folder / "render" / "stage.json").write_text("{}")
    return folder


def test_export_command_writes_both_trackers(tmp_path, capsys):
    from mitpiv.cli import main

    run = _fake_run(tmp_path / "run")
    assert main(["export", str(run), "--openlpt", str(tmp_path / "lpt"), "--openptv", str(tmp_path / "ptv")]) == 0
    out = capsys.readouterr().out
    assert "openlpt: 4 cameras x 2 frames (render images" in out and "openptv: 4 cameras" in out
    m = json.loads((tmp_path / "lpt" / "mitpiv_export.json").read_text())
    assert m["frame_rate_hz"] == pytest.approx(500.0) and m["sensors"] == ["cam0", "cam1", "cam2", "cam3"]
    assert m["gain"] == pytest.approx(255 / 4.5)  # the brightest frame: camera 3, frame 1
    img = cv2.imread(str(tmp_path / "lpt" / "imgFile/cam3/img00001.tif"), cv2.IMREAD_UNCHANGED)  # 1-based: cam2
    assert np.all(img == round(3.5 * 255 / 4.5))
    assert _read_config(tmp_path / "lpt" / "config.txt")[12] == "-3.0,3.0,-2.0,2.0,-1.0,1.0"
    assert (tmp_path / "ptv" / "img" / "cam4.10002").is_file()
    c = _read_openlpt_camera(tmp_path / "lpt" / "camFile" / "cam1.txt")
    p = _points(seed=5)
    assert np.max(np.abs(_openlpt_project(c, p) - (_cameras()[0].project(p) - 0.5))) < EXACT_PX


def test_export_command_refuses_a_run_without_images(tmp_path, capsys):
    from mitpiv.cli import main

    run = _fake_run(tmp_path / "run", images=False)
    assert main(["export", str(run), "--openlpt", str(tmp_path / "lpt")]) == 2
    assert "no rendered images" in capsys.readouterr().err
    assert _files(tmp_path / "lpt") == []
    assert main(["export", str(run)]) == 2 and "--openlpt DIR" in capsys.readouterr().err


#: Grey-weighted centroids of thresholded, 8-bit Gaussian blobs (sigma 1.2 px, threshold 10 of
#: 255) against their true centres: optv 0.3.2 finds them within 0.007 px here; peak locking
#: and 8-bit rounding allow a few hundredths. A half-pixel convention error would be 0.5 px.
CENTROID_PX = 0.05


def test_openptv_targets_share_mitpivs_pixel_convention(tmp_path):
    """OpenPTV's target recognition reports pixel coordinates in which pixel i spans
    [i, i + 1) (liboptv's targ_rec adds 0.5 to the grey-weighted index), so an export needs
    no half-pixel shift: blobs drawn at known mitpiv positions are found there."""
    cam = _cameras()[0]
    uv = np.array([[30.3, 40.7], [101.55, 22.2], [64.0, 88.45], [130.9, 100.1]])
    jj, ii = np.mgrid[0:120, 0:160]
    img = sum(np.exp(-((ii + 0.5 - u) ** 2 + (jj + 0.5 - v) ** 2) / (2 * 1.2**2)) for u, v in uv)
    m = export_openptv(tmp_path / "ptv", [[img]] * 4, [cam] * 4, lower_mm=[-1] * 3, upper_mm=[1] * 3,
                       gain=250.0, settings=OpenPTVSettings(gray_threshold=10.0))
    g = cv2.imread(str(tmp_path / "ptv" / "img" / "cam1.10001"), cv2.IMREAD_UNCHANGED).astype(np.float64)
    # liboptv's centroid written afresh: grey values above the threshold around each blob,
    # weighted by (g - thres), index + 0.5
    thr = 10.0
    for u, v in uv:
        win = (np.abs(ii + 0.5 - u) < 5) & (np.abs(jj + 0.5 - v) < 5) & (g > thr)
        wgt = (g - thr)[win]
        c = np.array([np.sum(ii[win] * wgt), np.sum(jj[win] * wgt)]) / wgt.sum() + 0.5
        assert np.hypot(*(c - [u, v])) < CENTROID_PX
    assert m["gain"] == 250.0
    if HAS_OPTV:
        from optv.parameters import ControlParams, TargetParams
        from optv.segmentation import target_recognition

        cpar = ControlParams(4)
        cpar.read_control_par(str(tmp_path / "ptv" / "parameters" / "ptv.par"))
        tpar = TargetParams()
        tpar.read(str(tmp_path / "ptv" / "parameters" / "targ_rec.par"))
        t = target_recognition(g.astype(np.uint8), tpar, 0, cpar)
        found = np.array([t[i].pos() for i in range(len(t))])
        assert len(found) == len(uv)
        d = np.min(np.linalg.norm(found[:, None] - uv[None], axis=2), axis=1)
        assert np.all(d < CENTROID_PX)


#: Centroid of a resampled Gaussian blob (sigma 1.2 px, 8 bit) against its undistorted
#: pinhole position, for a lens shifting points by 4 % at 60 px from the centre: measured
#: 0.001 - 0.048 px (bicubic interpolation, and the map's curvature across a blob; the same
#: centroid of a blob drawn at the pinhole position is off by < 0.007 px). A blob left at its
#: distorted position would be more than 2 px away.
REMAP_PX = 0.06


def test_export_openlpt_undistort(tmp_path):
    """The work-around for openlpt's distorted stereo matching: frames resampled onto the
    camera's undistorted pinhole image, cameras written without distortion."""
    k1 = -300.0  # a 4 % shift at 60 px from the centre of this small sensor (f = 5000 px)
    cam = _cameras(Distortion(k1=k1))[0]
    f, (cx, cy) = cam.focal_px, cam.principal_point_px
    uv_pin = np.array([[20.3, 15.7], [140.2, 100.9], [30.0, 105.5], [80.4, 60.2]])
    # Brown-Conrady with k1 only, written afresh: where the distorted camera images them
    x, y = (uv_pin[:, 0] - cx) / f, (uv_pin[:, 1] - cy) / f
    rad = 1 + k1 * (x * x + y * y)
    uv_dist = np.stack([f * x * rad + cx, f * y * rad + cy], axis=1)
    jj, ii = np.mgrid[0:120, 0:160]
    img = sum(np.exp(-((ii + 0.5 - u) ** 2 + (jj + 0.5 - v) ** 2) / (2 * 1.2**2)) for u, v in uv_dist)
    m = export_openlpt(tmp_path / "lpt", [[img]] * 4, [cam] * 4, lower_mm=[-2] * 3, upper_mm=[2] * 3, undistort=True,
                       gain=200.0)
    assert m["undistorted_images"]
    c = _read_openlpt_camera(tmp_path / "lpt" / "camFile" / "cam1.txt")
    assert np.all(c["dist"] == 0) and np.allclose(c["K"], cam.K - [[0, 0, 0.5], [0, 0, 0.5], [0, 0, 0]])
    assert np.max(np.linalg.norm(uv_pin - uv_dist, axis=1)) > 2.0
    g = cv2.imread(str(tmp_path / "lpt" / "imgFile" / "cam1" / "img00000.tif"), cv2.IMREAD_UNCHANGED).astype(float)
    for u, v in uv_pin:
        win = (np.abs(ii + 0.5 - u) < 4) & (np.abs(jj + 0.5 - v) < 4)
        wgt = g[win]
        cen = np.array([np.sum((ii[win] + 0.5) * wgt), np.sum((jj[win] + 0.5) * wgt)]) / wgt.sum()
        assert np.hypot(*(cen - [u, v])) < REMAP_PX
