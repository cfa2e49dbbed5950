"""A user's DLT or third-order polynomial calibration table (mitpiv.io.calibration_tables)
becomes cameras the renderer uses and mappings the reconstruction uses.

References are independent of the code under test: the DLT parameters are written afresh
here in float64 from a known K, R, t (Abdel-Aziz & Karara's formula), the decomposition is
compared with OpenCV's ``decomposeProjectionMatrix``, and the Soloff polynomial is fitted
here by ``numpy.linalg.lstsq`` on monomials spelled out in this file."""

import json

import cv2
import numpy as np
import pytest

from mitpiv.errors import ConfigError, FileFormatError
from mitpiv.io import (
    read_dlt_cameras,
    read_dlt_table,
    read_polynomial_cameras,
    read_polynomial_table,
    write_dlt_table,
    write_polynomial_table,
)
from mitpiv.physics.camera import PinholeCamera, look_at_rotation
from mitpiv.physics.distortion import Distortion

#: A DLT and the camera it is decomposed into project the same float64 rays: rounding only
#: (pixel coordinates ~1e3, a few dozen operations: ~1e-12; the brief's bound 1e-9 px).
DLT_PROJECTION_ATOL_PX = 1e-9
#: The Soloff polynomial fitted here to a Brown-Conrady camera over the volume leaves
#: <= 0.01 px (measured 0.003 px max); the pinhole + Brown-Conrady camera fitted to the
#: polynomial adds its own 0.003 px: 0.02 px bounds their sum with margin, far below the
#: 0.1 px default tolerance of the import.
POLY_CAMERA_ATOL_PX = 0.02

SIZE = (640, 480)
PITCH_UM = 6.5
VOLUME = [-10.0, 10.0, -8.0, 8.0, -4.0, 4.0]
RNG = np.random.default_rng(7)
POINTS = RNG.uniform([-10, -8, -4], [10, 8, 4], (300, 3))


def known_krt(i=0):
    """A camera 400 mm from the origin, 60 mm lens on 6.5 um pixels, off-centre principal point."""
    pos = np.array([150.0 * np.cos(i), -350.0, 120.0 + 20 * i])
    r = look_at_rotation(pos, [1.0, -0.5, 0.2])
    k = np.array([[9230.7692307692, 0.0, 331.25], [0.0, 9230.7692307692, 236.75], [0.0, 0.0, 1.0]])
    return k, r, -r @ pos


def dlt_of(k, r, t, first_pixel_centre=0.0):
    """L1..L11 of u = (L1 X + L2 Y + L3 Z + L4) / (L9 X + L10 Y + L11 Z + 1), pixels with the
    first pixel's centre at ``first_pixel_centre`` (mitpiv's K has it at 0.5)."""
    k = k.copy()
    k[0, 2] += first_pixel_centre - 0.5
    k[1, 2] += first_pixel_centre - 0.5
    p = k @ np.hstack([r, t.reshape(3, 1)])
    return (p / p[2, 3]).ravel()[:11]


def dlt_project(L, pts):
    """Abdel-Aziz & Karara's formula, float64."""
    X, Y, Z = pts.T
    w = L[8] * X + L[9] * Y + L[10] * Z + 1.0
    return np.stack([(L[0] * X + L[1] * Y + L[2] * Z + L[3]) / w, (L[4] * X + L[5] * Y + L[6] * Z + L[7]) / w], -1)


def write_dlt_csv(path, rows, settings=""):
    head = "camera," + ",".join(f"L{i}" for i in range(1, 12))
    path.write_text(settings + head + "\n" + "".join(f"{n}," + ",".join(repr(float(v)) for v in L) + "\n"
                                                      for n, L in rows))
    return path


def test_dlt_written_here_projects_like_the_camera(tmp_path):
    k, r, t = known_krt()
    L = dlt_of(k, r, t)  # OpenCV-style pixels (first centre at 0)
    f = write_dlt_csv(tmp_path / "dlt.csv", [("cam0", L)], "# image_width = 640\n# image_height = 480\n")
    cam, info = read_dlt_cameras(f, camera="cam0", pixel_pitch_um=PITCH_UM)
    assert cam.resolution == SIZE and cam.focal_length_mm == pytest.approx(60.0, rel=1e-9)
    np.testing.assert_allclose(cam.project(POINTS), dlt_project(L, POINTS) + 0.5, atol=DLT_PROJECTION_ATOL_PX, rtol=0)
    assert info["max_residual_px"] < DLT_PROJECTION_ATOL_PX
    # the decomposition agrees with OpenCV's (camera centre and rotation)
    kc, rc, c_h = cv2.decomposeProjectionMatrix(np.append(L, 1.0).reshape(3, 4))[:3]
    np.testing.assert_allclose(cam.position_mm, (c_h[:3] / c_h[3]).ravel(), atol=1e-9)
    s = np.sign(np.diag(kc))  # OpenCV's RQ may flip axis signs
    np.testing.assert_allclose(cam.rotation, np.diag(s) @ rc, atol=1e-12)


def test_dlt_conventions_and_projection_matrix(tmp_path):
    """Length unit (m), MATLAB pixels (first centre at 1), a 3x4 matrix at any scale and sign."""
    k, r, t = known_krt(1)
    want = PinholeCamera(SIZE, 60.0, PITCH_UM, rotation=r, position_mm=-r.T @ t, principal_point_px=(k[0, 2], k[1, 2]))
    L_m = dlt_of(k, r, t / 1000.0, first_pixel_centre=1.0)  # world in metres: X / 1000, so t / 1000
    f = write_dlt_csv(tmp_path / "m.csv", [("a", L_m)], "# length_unit_mm = 1000  # metres\n# first_pixel_centre_px = 1\n")
    cam, _ = read_dlt_cameras(f, camera=0, pixel_pitch_um=PITCH_UM, resolution=SIZE)
    np.testing.assert_allclose(cam.project(POINTS), want.project(POINTS), atol=1e-8)
    p = -3.7 * (k @ np.hstack([r, t.reshape(3, 1)]))  # mitpiv pixels: first centre at 0.5
    g = tmp_path / "p.json"
    g.write_text(json.dumps({"format": "dlt", "first_pixel_centre_px": 0.5, "image_width": SIZE[0],
                             "image_height": SIZE[1], "pixel_pitch_um": PITCH_UM,
                             "cameras": [{"name": "cam0", "P": p.tolist()}]}))
    cam2, _ = read_dlt_cameras(g, camera="cam0")
    np.testing.assert_allclose(cam2.project(POINTS), want.project(POINTS), atol=DLT_PROJECTION_ATOL_PX)


@pytest.mark.parametrize("suffix", [".csv", ".json"])
def test_camera_dlt_camera_round_trip(tmp_path, suffix):
    cams = []
    for i in range(4):
        k, r, t = known_krt(i)
        cams.append(PinholeCamera(SIZE, 60.0, PITCH_UM, rotation=r, position_mm=-r.T @ t,
                                  principal_point_px=(k[0, 2], k[1, 2]), f_number=8.0, focus_distance_mm=400.0))
    f = write_dlt_table(tmp_path / f"dlt{suffix}", cams, names=[f"cam{i}" for i in range(4)], length_unit_mm=10.0)
    back = read_dlt_cameras(f, expected_cameras=4, volume_mm=VOLUME)
    assert [i["name"] for _, i in back] == ["cam0", "cam1", "cam2", "cam3"]
    for c, (b, _) in zip(cams, back, strict=True):
        assert b.resolution == c.resolution and b.pixel_pitch_um == c.pixel_pitch_um
        np.testing.assert_allclose(b.project(POINTS), c.project(POINTS), atol=DLT_PROJECTION_ATOL_PX)
        np.testing.assert_allclose(b.position_mm, c.position_mm, atol=1e-9)
        np.testing.assert_allclose(b.rotation, c.rotation, atol=1e-12)
    # reconstruction mappings by name (the images' sensor ids), in the images' order
    from mitpiv.reconstruct.mapping import PinholeMapping, mappings_from_calibration

    maps = mappings_from_calibration(f, names=["cam3", "cam1"])
    assert all(isinstance(m, PinholeMapping) for m in maps)
    np.testing.assert_allclose(maps[0].project(POINTS), cams[3].project(POINTS), atol=DLT_PROJECTION_ATOL_PX)
    np.testing.assert_allclose(maps[1].project(POINTS), cams[1].project(POINTS), atol=DLT_PROJECTION_ATOL_PX)
    # the table's numbers are those of the formula written here
    recs, settings = read_dlt_table(f)
    assert settings["length_unit_mm"] == 10.0
    k, r, t = known_krt(2)
    np.testing.assert_allclose(recs[2]["L"], dlt_of(k, r, t / 10.0), rtol=1e-12)


def test_skew_and_non_square_pixels(tmp_path):
    k, r, t = known_krt()
    k_bad = k.copy()
    k_bad[1, 1] *= 1.002  # 0.2 % aspect error
    k_bad[0, 1] = 0.5  # skew [px]
    L = dlt_of(k_bad, r, t)
    f = write_dlt_csv(tmp_path / "bad.csv", [("left", L)])
    with pytest.raises(ConfigError, match=r"camera 'left'.*fx = .*fy = .*skew.*max_residual_px = 0.1"):
        read_dlt_cameras(f, camera="left", pixel_pitch_um=PITCH_UM, resolution=SIZE)
    cam, info = read_dlt_cameras(f, camera="left", pixel_pitch_um=PITCH_UM, resolution=SIZE, max_residual_px=2.0)
    # the stated residual is the true one: the largest error over the image, at its corners,
    # between the exact DLT and the approximating camera (projected through both)
    corners = np.array([[0, 0], [SIZE[0], 0], [0, SIZE[1]], [SIZE[0], SIZE[1]]], float)  # mitpiv pixels
    k_file = k_bad.copy()
    k_file[:2, 2] -= 0.5  # the file's pixels: first centre at 0
    rays = np.linalg.solve(k_file, np.hstack([corners - 0.5, np.ones((4, 1))]).T).T  # camera frame
    pts = -r.T @ t + (rays @ r) * 400.0  # points on the DLT's corner rays, 400 mm out
    np.testing.assert_allclose(dlt_project(L, pts), corners - 0.5, atol=1e-9)  # they do project to the corners
    err = np.linalg.norm(cam.project(pts) - corners, axis=1)
    assert info["max_residual_px"] == pytest.approx(err.max(), rel=1e-9)
    assert 0.4 < info["max_residual_px"] < 2.0


# ---------------------------------------------------------------------- polynomial
#: Soloff's 19 monomials, spelled out here (in an order of this test's own), and z^3.
SOLOFF = {"1": (0, 0, 0), "x": (1, 0, 0), "y": (0, 1, 0), "z": (0, 0, 1), "x^2": (2, 0, 0), "x*y": (1, 1, 0),
          "y^2": (0, 2, 0), "x*z": (1, 0, 1), "y*z": (0, 1, 1), "z^2": (0, 0, 2), "x^3": (3, 0, 0),
          "x^2*y": (2, 1, 0), "x*y^2": (1, 2, 0), "y^3": (0, 3, 0), "x^2*z": (2, 0, 1), "x*y*z": (1, 1, 1),
          "y^2*z": (0, 2, 1), "x*z^2": (1, 0, 2), "y*z^2": (0, 1, 2)}


def distorted_camera():
    k, r, t = known_krt()
    return PinholeCamera(SIZE, 60.0, PITCH_UM, rotation=r, position_mm=-r.T @ t, principal_point_px=(331.25, 236.75),
                         distortion=Distortion(k1=-0.8, k2=3.0, p1=2e-3, p2=-1e-3))


def soloff_fit(cam, names, centre, scale):
    """Least squares written here: pixels (OpenCV convention) against the named monomials of
    normalised world points over the volume."""
    g = np.stack(np.meshgrid(*(np.linspace(VOLUME[2 * a], VOLUME[2 * a + 1], n) for a, n in enumerate((11, 11, 5))),
                             indexing="ij"), -1).reshape(-1, 3)
    q = (g - centre) / scale
    a = np.stack([q[:, 0] ** SOLOFF_X[n][0] * q[:, 1] ** SOLOFF_X[n][1] * q[:, 2] ** SOLOFF_X[n][2] for n in names], -1)
    coef, *_ = np.linalg.lstsq(a, cam.project(g) - 0.5, rcond=None)
    resid = np.abs(a @ coef - (cam.project(g) - 0.5)).max()
    return coef.T, resid


SOLOFF_X = {**SOLOFF, "z^3": (0, 0, 3)}


def poly_eval(coef, names, centre, scale, pts):
    q = (pts - centre) / scale
    a = np.stack([q[:, 0] ** SOLOFF_X[n][0] * q[:, 1] ** SOLOFF_X[n][1] * q[:, 2] ** SOLOFF_X[n][2] for n in names], -1)
    return a @ coef.T


def write_poly_csv(path, coef, names, centre, scale, settings="# volume_mm = -10 10 -8 8 -4 4\n", cam="cam0"):
    head = "camera,coordinate," + ",".join(names) + ",centre_x,centre_y,centre_z,scale_x,scale_y,scale_z\n"
    rows = "".join(f"{cam},{c}," + ",".join(repr(float(v)) for v in coef[i]) + "," +
                   ",".join(repr(float(v)) for v in (*centre, *scale)) + "\n" for i, c in enumerate("uv"))
    path.write_text(settings + head + rows)
    return path


def test_soloff_polynomial_drives_a_renderable_camera(tmp_path):
    true = distorted_camera()
    names = list(SOLOFF)
    centre, scale = np.array([0.0, 0.0, 0.0]), np.array([10.0, 8.0, 4.0])
    coef, fit_resid = soloff_fit(true, names, centre, scale)
    assert fit_resid < 0.01
    f = write_poly_csv(tmp_path / "poly.csv", coef, names, centre, scale)
    cam, info = read_polynomial_cameras(f, camera="cam0", pixel_pitch_um=PITCH_UM, resolution=SIZE)
    np.testing.assert_allclose(cam.project(POINTS), true.project(POINTS), atol=POLY_CAMERA_ATOL_PX)
    # the reported residual is the camera's distance to the polynomial, measured here too
    err = np.linalg.norm(cam.project(POINTS) - (poly_eval(coef, names, centre, scale, POINTS) + 0.5), axis=1)
    assert err.max() <= info["max_px"] * 1.5 + 1e-4 and info["max_px"] < 0.1
    # the reconstruction maps through the polynomial itself
    from mitpiv.reconstruct.mapping import PolynomialMapping, mappings_from_calibration

    (m,) = mappings_from_calibration(f)
    assert isinstance(m, PolynomialMapping)
    np.testing.assert_allclose(m.project(POINTS), poly_eval(coef, names, centre, scale, POINTS) + 0.5, atol=1e-9)


def test_polynomial_cubic_json_and_round_trip(tmp_path):
    true = distorted_camera()
    names = list(SOLOFF_X)[::-1]  # 20 terms, reversed order, named in the JSON
    centre, scale = np.array([0.0, 0.0, 0.0]), np.array([1.0, 1.0, 1.0])  # raw mm
    coef, _ = soloff_fit(true, names, centre, scale)
    f = tmp_path / "poly.json"
    f.write_text(json.dumps({"format": "polynomial", "terms": names, "volume_mm": VOLUME, "pixel_pitch_um": PITCH_UM,
                             "image_width": SIZE[0], "image_height": SIZE[1],
                             "cameras": [{"name": "c", "u": coef[0].tolist(), "v": coef[1].tolist()}]}))
    (rec,), _ = read_polynomial_table(f)
    assert len(rec["terms"]) == 20
    cam, info = read_polynomial_cameras(f, camera="c")
    np.testing.assert_allclose(cam.project(POINTS), true.project(POINTS), atol=POLY_CAMERA_ATOL_PX)
    # our camera -> polynomial table -> camera
    for suffix in (".csv", ".json"):
        g = write_polynomial_table(tmp_path / f"ours{suffix}", [true, true], names=["a", "b"], volume_mm=VOLUME)
        back = read_polynomial_cameras(g, expected_cameras=2)
        for b, _ in back:
            np.testing.assert_allclose(b.project(POINTS), true.project(POINTS), atol=POLY_CAMERA_ATOL_PX)


def test_a_polynomial_no_pinhole_fits_is_refused(tmp_path):
    true = distorted_camera()
    names = list(SOLOFF)
    centre, scale = np.zeros(3), np.array([10.0, 8.0, 4.0])
    coef, _ = soloff_fit(true, names, centre, scale)
    coef[0, names.index("x^2*y")] += 3.0  # 3 px of a warp no lens makes
    f = write_poly_csv(tmp_path / "warp.csv", coef, names, centre, scale)
    with pytest.raises(ConfigError, match=r"camera 'cam0'.*reprojects up to .* px.*max_residual_px = 0.1"):
        read_polynomial_cameras(f, pixel_pitch_um=PITCH_UM, resolution=SIZE)
    cams = read_polynomial_cameras(f, pixel_pitch_um=PITCH_UM, resolution=SIZE, max_residual_px=10.0)
    assert cams[0][1]["max_px"] > 0.1


# ---------------------------------------------------------------------- bad inputs
def test_bad_tables_give_clear_errors_and_write_nothing(tmp_path):
    k, r, t = known_krt()
    L = dlt_of(k, r, t)
    d = tmp_path / "in"
    d.mkdir()
    # wrong coefficient count
    f = d / "ten.csv"
    f.write_text("camera," + ",".join(f"L{i}" for i in range(1, 11)) + "\ncam0," + ",".join(map(str, L[:10])) + "\n")
    with pytest.raises(FileFormatError, match="11 DLT parameters"):
        read_dlt_table(f)
    g = d / "twelve.json"
    g.write_text(json.dumps({"cameras": [{"name": "cam0", "L": [*L.tolist(), 0.0]}]}))
    with pytest.raises(FileFormatError, match="12 DLT parameters; the DLT has exactly 11"):
        read_dlt_table(g)
    # NaN
    bad = L.copy()
    bad[4] = np.nan
    with pytest.raises(FileFormatError, match=r"camera 'cam0' L\[4\] = 'nan' is not finite"):
        read_dlt_table(write_dlt_csv(d / "nan.csv", [("cam0", bad)]))
    # singular DLT: the third row of the 3x3 block a combination of the first two
    sing = L.copy()
    sing[8:11] = 1e-4 * (L[0:3] + L[4:7])
    with pytest.raises(ConfigError, match="singular"):
        read_dlt_cameras(write_dlt_csv(d / "sing.csv", [("cam0", sing)]), pixel_pitch_um=PITCH_UM, resolution=SIZE)
    # a polynomial whose volume is not given
    names = list(SOLOFF)
    coef, _ = soloff_fit(distorted_camera(), names, np.zeros(3), np.ones(3))
    p = write_poly_csv(d / "novol.csv", coef, names, np.zeros(3), np.ones(3), settings="")
    with pytest.raises(ConfigError, match="volume_mm"):
        read_polynomial_cameras(p, pixel_pitch_um=PITCH_UM, resolution=SIZE)
    # a missing term
    q = d / "18.csv"
    q.write_text(p.read_text().replace(",y*z^2,", ",w,"))
    with pytest.raises(FileFormatError, match="not a monomial name"):
        read_polynomial_table(q)
    q.write_text("camera,coordinate," + ",".join(names[:-1]) + "\ncam0,u," + ",".join(["1"] * 18) + "\ncam0,v," +
                 ",".join(["1"] * 18) + "\n")
    with pytest.raises(FileFormatError, match=r"Missing: \['yz2'\]"):
        read_polynomial_table(q)
    # a file with 3 cameras for a scene of 4
    three = write_dlt_csv(d / "three.csv", [(f"cam{i}", dlt_of(*known_krt(i))) for i in range(3)])
    with pytest.raises(ConfigError, match=r"holds 3 camera\(s\) \(cam0, cam1, cam2\) but the scene has 4"):
        read_dlt_cameras(three, expected_cameras=4, pixel_pitch_um=PITCH_UM, resolution=SIZE)
    with pytest.raises(ConfigError, match="none named 'cam3'"):
        read_dlt_cameras(three, camera="cam3", pixel_pitch_um=PITCH_UM, resolution=SIZE)
    # no pixel pitch
    with pytest.raises(ConfigError, match="pixel_pitch_um"):
        read_dlt_cameras(three, camera="cam0", resolution=SIZE)
    # writers refuse what the format cannot hold, and leave nothing behind
    out = tmp_path / "out"
    out.mkdir()
    with pytest.raises(ConfigError, match="distortion"):
        write_dlt_table(out / "d.csv", [distorted_camera()])
    with pytest.raises(ConfigError, match="volume_mm"):
        write_polynomial_table(out / "p.csv", [distorted_camera()])
    assert list(out.iterdir()) == []


def test_tables_drive_the_renderer(tmp_path, capsys):
    """A 4-camera DLT table: each sensor takes the camera named by its id, and its particle
    images land where Abdel-Aziz & Karara's formula puts them; a polynomial table gives the
    fitted camera; a table with 3 cameras for a sensor cam3 fails at load, rendering nothing."""
    import mitsuba as mi

    from mitpiv.cli import main
    from mitpiv.io import write_particles_ply
    from mitpiv.render.scene import load_dict

    Ls = [dlt_of(*known_krt(i)) for i in range(4)]
    table = write_dlt_csv(tmp_path / "cams.csv", [(f"cam{i}", L) for i, L in enumerate(Ls)],
                          f"# pixel_pitch_um = {PITCH_UM}\n# image_width = 640\n# image_height = 480\n")
    pts = RNG.uniform([-6, -5, -1], [6, 5, 1], (80, 3))
    uv = dlt_project(Ls[2], pts) + 0.5
    frac = uv - np.floor(uv)
    pts = pts[np.all((frac > 0.05) & (frac < 0.95), axis=1) & np.all((uv > 1) & (uv < np.array(SIZE) - 1), axis=1)][:10]
    uv = dlt_project(Ls[2], pts) + 0.5
    write_particles_ply(tmp_path / "p.ply", pts, np.full(len(pts), 2.0), proxy_radius_mm=0.01)
    film = {"type": "hdrfilm", "width": SIZE[0], "height": SIZE[1], "pixel_format": "luminance",
            "rfilter": {"type": "box"}}
    sc = load_dict({
        "type": "scene", "integrator": {"type": "particle_tracer"},
        "cam2": {"type": "distorted_pinhole", "id": "cam2", "calibration": str(table), "film": film},
        "laser": {"type": "laser_sheet", "id": "laser", "thickness": 40.0},
        "particles": {"type": "ellipsoidsmesh", "filename": str(tmp_path / "p.ply"), "extent": 1.0,
                      "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.0}},
                      "emitter": {"type": "tracer_particles", "sheet": {"type": "ref", "id": "laser"}}}})
    img = np.array(mi.render(sc, spp=1, seed=0), dtype=np.float64)[..., 0]
    lit = np.argwhere(img > 0)[:, ::-1] + 0.5
    order = lambda a: a[np.lexsort((a[:, 1], a[:, 0]))]  # noqa: E731 - compare as sets of pixels
    assert len(lit) == len(pts)
    np.testing.assert_allclose(order(lit), order(np.floor(uv) + 0.5), atol=1e-6)
    # a polynomial table of our own camera drives a sensor too
    true = distorted_camera()
    poly = write_polynomial_table(tmp_path / "poly.json", [true], names=["cam0"], volume_mm=VOLUME)
    s = load_dict({"type": "distorted_pinhole", "calibration": str(poly), "calibration_max_residual_px": 0.05,
                   "film": film})
    np.testing.assert_allclose(s.camera.project(POINTS), true.project(POINTS), atol=POLY_CAMERA_ATOL_PX)
    assert s.calibration_info["max_px"] < 0.05
    # three cameras in the file, a scene of four: a clear error, nothing written
    write_dlt_csv(tmp_path / "three.csv", [(f"cam{i}", L) for i, L in enumerate(Ls[:3])],
                  f"# pixel_pitch_um = {PITCH_UM}\n")
    write_particles_ply(tmp_path / "p0.ply", pts, np.full(len(pts), 2.0), proxy_radius_mm=0.01)
    xml = tmp_path / "scene.xml"
    xml.write_text(
        '<scene version="3.0.0"><default name="frame" value="0"/><integrator type="particle_tracer"/>'
        '<emitter type="laser_sheet" id="laser"><float name="thickness" value="40"/></emitter>'
        '<shape type="ellipsoidsmesh"><string name="filename" value="p$frame.ply"/><float name="extent" value="1"/>'
        '<emitter type="tracer_particles"><ref name="sheet" id="laser"/></emitter></shape>' + "".join(
            f'<sensor type="distorted_pinhole" id="cam{i}"><string name="calibration" value="three.csv"/>'
            f'<film type="hdrfilm"><integer name="width" value="640"/><integer name="height" value="480"/></film>'
            f'</sensor>' for i in range(4)) + "</scene>")
    out = tmp_path / "render"
    assert main(["render", str(xml), "--out", str(out), "--frames", "0"]) != 0
    assert "holds 3 camera(s) (cam0, cam1, cam2), none named 'cam3'" in capsys.readouterr().err
    assert not out.exists() or not any(out.rglob("*"))
    # a $name the scene does not use is named in the error (Mitsuba lists it on a second line)
    xml.write_text(xml.read_text().replace('<default name="frame" value="0"/>',
                                           '<default name="frame" value="0"/><default name="distance_mm" value="1"/>'))
    assert main(["render", str(xml), "--out", str(out), "--frames", "0"]) != 0
    assert "parameters $distance_mm=1 are not used by the scene XML" in capsys.readouterr().err


def test_reconstruction_maps_through_the_table(tmp_path):
    """reconstruct_images with a table's mappings (what `mitpiv reconstruct --calibration`
    passes) equals reconstruct_volume through the same mappings, whatever cameras the
    metadata holds; a table with fewer cameras than images is refused."""
    from mitpiv.grid import VoxelGrid
    from mitpiv.reconstruct.images import reconstruct_images
    from mitpiv.reconstruct.mapping import mappings_from_calibration
    from mitpiv.reconstruct.tomo import reconstruct_volume

    cams = [PinholeCamera((64, 48), 60.0, 65.0, rotation=known_krt(i)[1], position_mm=-known_krt(i)[1].T @ known_krt(i)[2])
            for i in range(3)]
    f = write_polynomial_table(tmp_path / "poly.csv", cams, volume_mm=VOLUME)
    maps = mappings_from_calibration(f)
    images = [np.random.default_rng(i).random((48, 64)).astype(np.float32) for i in range(3)]
    metas = [{"camera": PinholeCamera((64, 48), 50.0, 65.0).to_dict()} for _ in range(3)]  # wrong on purpose
    grid = VoxelGrid.from_bounds((-10, -8, -4), (10, 8, 4), 1.0)
    got, _ = reconstruct_images(images, metas, grid, "mlos", mappings=maps)
    want, _ = reconstruct_volume(images, maps, grid, "mlos")
    assert np.count_nonzero(got) > 0.5 * got.size  # the cameras see the volume
    np.testing.assert_array_equal(got, want)
    with pytest.raises(ConfigError, match=r"2 camera mapping\(s\) for 3 image\(s\)"):
        reconstruct_images(images, metas, grid, "mlos", mappings=maps[:2])
