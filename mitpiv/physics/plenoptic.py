"""Plenoptic 1.0 (unfocused light-field) camera geometry in float64 NumPy.

A thin main lens (focal length ``f``, aperture diameter ``D``) is focused on an object
plane at distance ``s_o``; the microlens array (MLA) sits at the image distance
``s_i = 1 / (1/f - 1/s_o)``; each lenslet (pitch ``p``, focal length ``f_m``) is focused
at infinity, so the pixels ``g = f_m`` behind it record an image of the main-lens
aperture. Nothing is paraxial in the plugin: the ideal thin lens is exactly linear in the
ray *tangents* ``t = (dx/dz, dy/dz)`` (``t_out = t_in - (x - c) / f``, the refraction of
Mitsuba's ``thinlens``), so the ray-transfer bookkeeping here is exact for every ray.

Frames
------
Camera-local frame = Mitsuba's (x left, y up, z forward along the optical axis), main
lens at ``z = 0``, MLA plane at ``z = -s_i``, sensor at ``z = -(s_i + g)``. The
*sensor frame* ``(X, Y)`` [mm] is that local (x, y) on the MLA and sensor planes; the
image is read out rotated by 180 degrees, so pixel ``(u, v)`` (continuous, pixel
``(i, j)`` spans ``[i, i+1)``) sits at ``X = (u - W/2) p_px``, ``Y = (v - H/2) p_px``
and the raw image shows the scene upright. Lenslet centres are given in that frame:
``rect`` layout = square lattice; ``hex`` = rows spaced ``p sqrt(3)/2`` with odd rows
shifted by ``p/2``; the whole array may be rotated and offset (misalignment).

The lenslet images are centred on ``C_k = c_k (1 + g/s_i)``, the projection of the
lenslet centre from the main-lens centre, not on the lenslet centres themselves; a pixel
at ``C_k + u`` looks through lenslet ``k`` at the main-lens aperture point
``a = -u s_i / g`` (the basis of :mod:`mitpiv.lightfield`).

The camera satisfies the camera contract (:class:`mitpiv.physics.camera.Camera`):
:meth:`PlenopticCamera.project` is the image point of a world point, the chief ray
through the main-lens centre onto the MLA plane, ``X = -s_i (x, y) / z`` (local frame),
scaled to the sensor by ``1 + g/s_i`` like the lenslet-image centres. It is the pinhole
projection of a camera with focal length ``s_i + g`` at the main-lens centre: the pixel
(on the lenslet-image lattice) round which a point's light gathers, whatever its depth.

Design calculators (depth of field, depth resolution, pixel bookkeeping) follow the
geometric construction of Deem et al. (2016, Meas. Sci. Technol. 27 084003): a point is
in focus in a refocused image while its blur spot on the MLA plane stays within one
lenslet, and in a perspective (sub-aperture) view while the blur through one angular
sample of the aperture (``D / n_u``) stays within one lenslet.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from mitpiv.errors import ConfigError, check_positive
from mitpiv.physics.camera import on_sensor
from mitpiv.physics.distortion import Distortion, distort, distort_jacobian, fold_radius, undistort

__all__ = ["PlenopticCamera", "PRESETS", "preset", "PAPER_003", "paper_003_camera", "thin_lens_image_distance",
           "alpha_from_z_geom", "dof_limits_geom", "depth_resolution_geom", "ltpr"]

_OWNER = "plenoptic"

#: Reference cameras. Lytro-like: the camera of multi-plenoptic PIV studies (main lens
#: 10 mm f/2, 14 um lenslets f/2, 328x328 lenslets, 1.4 um pixels). LF-PIV: hexagonal
#: MLA on 5.5 um pixels (the 6600x4400 sensor of in-house LF-PIV cameras), 50 mm f/2.8 main
#: lens, lenslet f-number matched to the image-side f-number, PMR 7, 14 or 28.
PRESETS: dict[str, dict] = {
    "lytro_like": dict(resolution=(3280, 3280), pixel_pitch_um=1.4, focal_length_mm=10.0, f_number=2.0,
                       focus_distance_mm=100.0, mla_pitch_um=14.0, mla_focal_length_um=28.0, mla_layout="rect",
                       mla_count=(328, 328)),
    # Fahringer & Thurow's multi-plenoptic study (Table 1): the Lytro-like camera focused at
    # S_o / p_M = 8 (S_o = 40 mm for the 5 mm aperture), 10 pixels of 1.4 um per 14 um lenslet.
    "multiplenoptic_paper": dict(resolution=(3280, 3280), pixel_pitch_um=1.4, focal_length_mm=10.0, f_number=2.0,
                                 focus_distance_mm=40.0, mla_pitch_um=14.0, mla_focal_length_um=28.0,
                                 mla_layout="rect", mla_count=(328, 328)),
}
for _n in (800, 1600):
    for _pmr in (7, 14, 28):
        PRESETS[f"lfpiv_hex_{_n}_pmr{_pmr}"] = dict(
            resolution=(_n, _n), pixel_pitch_um=5.5, focal_length_mm=50.0, f_number=2.8, focus_distance_mm=250.0,
            mla_pitch_um=5.5 * _pmr, mla_focal_length_um=None, mla_layout="hex", mla_count=None)


#: The plenoptic camera of the plenoptic-vs-DIH drop-fragment study (seed paper 003, ch. II.B
#: and IV): Imperx B6640 / KAI-29050 CCD, 6600 x 4400 px of 5.5 um; 471 x 362 hexagonally
#: arranged lenslets of 77 um pitch ("about 14 pixels across") about 308 um from the sensor
#: (taken as the lenslet focal length and gap: f/4 lenslets); 105 mm Nikon macro main lens.
#: The magnification is the one that reproduces both ends of the paper's alpha range through
#: its eq. 11 (drop impact: alpha 0.914-1.139 for +-30 mm -> |M| = 0.8235, a 44.1 x 29.4 mm
#: field, the paper's "about 29.5 x 43.7 mm"; pellets: 0.923-1.259 for +-200 mm -> |M| =
#: 0.2829, 128.3 x 85.5 mm, the paper's "86 x 127 mm"). The paper does not state the
#: aperture: f/2.8, the lens's widest, for the drop impact (its f-number-matched value, f/2.19
#: at this magnification, is beyond the lens; the lenslet images underfill to ~11 px); for
#: the pellets the lens is stopped down to the matched f/3.12 (f/2.8 would overfill the
#: lenslets at |M| = 0.28). Keys: "drop_impact", "pellets".
PAPER_003: dict[str, dict] = {}
for _case, _m, _n in (("drop_impact", 0.8235, 2.8), ("pellets", 0.2829, 4.0 / 1.2829)):
    PAPER_003[_case] = dict(resolution=(6600, 4400), pixel_pitch_um=5.5, focal_length_mm=105.0, f_number=_n,
                            focus_distance_mm=105.0 * (1.0 + _m) / _m, mla_pitch_um=77.0, mla_focal_length_um=308.0,
                            mla_layout="hex", mla_count=(471, 362))
    PRESETS[f"paper003_{_case}"] = PAPER_003[_case]


def paper_003_camera(case: str = "drop_impact", *, crop_px: tuple[int, int] | None = None,
                     distortion: Distortion | None = None, **overrides) -> PlenopticCamera:
    """The seed paper 003 plenoptic camera (:data:`PAPER_003`), optionally cropped.

    Parameters
    ----------
    case : "drop_impact" | "pellets"
        The focus (field of view) of the experiment.
    crop_px : (int, int), optional
        A centred crop of the sensor, (width, height) [px]: every optical parameter stays
        the paper's; the lenslet array fills the crop (quick runs: a 29 MP raw image and its
        1000-plane stack do not fit in memory at once).
    distortion : Distortion, optional
        Radial distortion of the main lens (see :class:`PlenopticCamera`).
    overrides
        Any other :class:`PlenopticCamera` field.
    """
    if case not in PAPER_003:
        raise ConfigError(f"paper_003_camera: 'case' must be one of {sorted(PAPER_003)}, got {case!r}.")
    kw = dict(PAPER_003[case])
    if crop_px is not None:
        cw, ch = (int(v) for v in crop_px)
        if not (2 <= cw <= 6600 and 2 <= ch <= 4400):
            raise ConfigError(f"paper_003_camera: 'crop_px' must be (width, height) within 6600 x 4400 px, got {crop_px!r}.")
        kw.update(resolution=(cw, ch), mla_count=None)
    if distortion is not None:
        kw["distortion"] = distortion
    kw.update(overrides)
    return PlenopticCamera(**kw)


def preset(name: str, **overrides) -> PlenopticCamera:
    """A :class:`PlenopticCamera` from :data:`PRESETS`, with any field overridden."""
    if name not in PRESETS:
        raise ConfigError(f"plenoptic: unknown preset {name!r}; choose one of {sorted(PRESETS)}.")
    return PlenopticCamera(**{**PRESETS[name], **overrides})


def thin_lens_image_distance(focal_length_mm: float, object_distance_mm):
    """Image distance ``1 / (1/f - 1/s_o)`` [mm] (``s_o > f``)."""
    so = np.asarray(object_distance_mm, dtype=float)
    return focal_length_mm * so / (so - focal_length_mm)


@dataclass
class PlenopticCamera:
    """Geometry of a plenoptic 1.0 camera; see the module docstring for the frames.

    Parameters
    ----------
    resolution : (int, int)
        Sensor width and height [px].
    pixel_pitch_um : float
    focal_length_mm : float
        Main-lens focal length.
    f_number : float, optional
        Main-lens f-number ``f / D`` (or give ``aperture_diameter_mm``).
    aperture_diameter_mm : float, optional
    focus_distance_mm : float
        Object distance in focus on the MLA (from the lens), ``> focal_length_mm``.
    mla_pitch_um : float
        Lenslet pitch (centre spacing along a row).
    mla_focal_length_um : float, optional
        Default: f-number matched, ``p * s_i / D``.
    mla_layout : "rect" | "hex"
    mla_count : (int, int), optional
        Lenslets per row and rows; default: as many as fit on the sensor.
    mla_rotation_deg : float
        Rotation of the array relative to the pixel grid (``|angle| <= 30 deg``).
    mla_offset_um : (float, float)
        Shift of the array centre from the sensor centre (sensor frame).
    mla_gap_um : float, optional
        MLA-to-sensor distance; default the lenslet focal length.
    to_world_mitsuba : (4, 4) array
        Camera pose (Mitsuba convention), main-lens centre at the translation.
    distortion : Distortion, optional
        Radial (Brown-Conrady k1, k2, k3; no tangential terms) distortion of the main lens,
        a property of the lens, so every ray through it is bent: a ray leaving an object
        point with object-side tangent ``t = (P - a)_xy / (P - a)_z`` (through lens point
        ``a``) is refracted as the ideal thin lens refracts the tangent
        ``t R(|t|^2)``, ``R = 1 + k1 r^2 + k2 r^4 + k3 r^6`` (the distortion of
        :mod:`mitpiv.physics.distortion` on the normalised coordinates ``t``). For the chief
        ray (``a = 0``) ``t`` is the point's normalised image coordinate, so its image moves
        radially by the model's amount, ``r -> r R(r^2)``, exactly as in a distorted pinhole
        camera; rays through other lens points see the same map of their own tangent. Over
        a symmetric aperture the bundle's centroid bends exactly as the chief ray (the
        cubic term) plus a uniform magnification change ``2 k1 <|a/z|^2>``; the same
        term is a spherical-aberration-like focus shift and blur (the paper's drop-impact
        camera at ``k1 = 0.3``: best focus of the ray bundle 0.30 mm nearer on the axis, a
        rendered dot card's sharpest plane 0.15 mm), which a dot-card dewarp absorbs as the
        real lens's would be. Camera tracing inverts the map (Newton,
        :func:`~mitpiv.physics.distortion.undistort`).
    """

    resolution: tuple[int, int]
    pixel_pitch_um: float
    focal_length_mm: float
    focus_distance_mm: float
    mla_pitch_um: float
    f_number: float | None = None
    aperture_diameter_mm: float | None = None
    mla_focal_length_um: float | None = None
    mla_layout: str = "rect"
    mla_count: tuple[int, int] | None = None
    mla_rotation_deg: float = 0.0
    mla_offset_um: tuple[float, float] = (0.0, 0.0)
    mla_gap_um: float | None = None
    to_world_mitsuba: np.ndarray = field(default_factory=lambda: np.eye(4))
    distortion: Distortion = field(default_factory=Distortion)

    def __post_init__(self) -> None:
        if isinstance(self.distortion, dict):
            self.distortion = Distortion(**self.distortion)
        if self.distortion is None:
            self.distortion = Distortion()
        if not isinstance(self.distortion, Distortion):
            raise ConfigError(f"{_OWNER}: 'distortion' must be a mitpiv.physics.distortion.Distortion, got "
                              f"{type(self.distortion).__name__}.")
        if self.distortion.has_tangential:
            raise ConfigError(f"{_OWNER}: the main-lens distortion is radial only (k1, k2, k3); got p1={self.distortion.p1}, "
                              f"p2={self.distortion.p2}. Set p1 = p2 = 0.")
        for k in ("k1", "k2", "k3"):
            if not math.isfinite(getattr(self.distortion, k)):
                raise ConfigError(f"{_OWNER}: distortion {k} must be finite, got {getattr(self.distortion, k)!r}.")
        w, h = (int(v) for v in self.resolution)
        if w != self.resolution[0] or h != self.resolution[1] or w < 2 or h < 2:
            raise ConfigError(f"{_OWNER}: 'resolution' must be two integers >= 2, got {self.resolution!r}.")
        self.resolution = (w, h)
        for name, unit in (("pixel_pitch_um", "um"), ("focal_length_mm", "mm"), ("focus_distance_mm", "mm"),
                           ("mla_pitch_um", "um")):
            setattr(self, name, check_positive(name, getattr(self, name), owner=_OWNER, unit=unit))
        if (self.f_number is None) == (self.aperture_diameter_mm is None):
            raise ConfigError(f"{_OWNER}: give exactly one of 'f_number' and 'aperture_diameter_mm'.")
        if self.f_number is not None:
            self.f_number = check_positive("f_number", self.f_number, owner=_OWNER)
            self.aperture_diameter_mm = self.focal_length_mm / self.f_number
        else:
            self.aperture_diameter_mm = check_positive("aperture_diameter_mm", self.aperture_diameter_mm, owner=_OWNER, unit="mm")
            self.f_number = self.focal_length_mm / self.aperture_diameter_mm
        if self.focus_distance_mm <= self.focal_length_mm * 1.0001:
            raise ConfigError(
                f"{_OWNER}: 'focus_distance_mm' ({self.focus_distance_mm}) must exceed the focal length "
                f"({self.focal_length_mm} mm): a closer object has no real image on the MLA."
            )
        if self.mla_layout not in ("rect", "hex"):
            raise ConfigError(f"{_OWNER}: 'mla_layout' must be 'rect' or 'hex', got {self.mla_layout!r}.")
        if self.mla_focal_length_um is None:
            self.mla_focal_length_um = self.mla_pitch_um * self.image_f_number
        self.mla_focal_length_um = check_positive("mla_focal_length_um", self.mla_focal_length_um, owner=_OWNER, unit="um")
        if self.mla_gap_um is None:
            self.mla_gap_um = self.mla_focal_length_um
        self.mla_gap_um = check_positive("mla_gap_um", self.mla_gap_um, owner=_OWNER, unit="um")
        if not abs(self.mla_rotation_deg) <= 30.0:
            raise ConfigError(f"{_OWNER}: 'mla_rotation_deg' must lie in [-30, 30] deg (a misalignment), got {self.mla_rotation_deg!r}.")
        self.mla_offset_um = (float(self.mla_offset_um[0]), float(self.mla_offset_um[1]))
        ox, oy = self.mla_offset_um
        half_w, half_h = 0.5 * w * self.pixel_pitch_um, 0.5 * h * self.pixel_pitch_um
        if not (math.isfinite(ox) and math.isfinite(oy)) or abs(ox) >= half_w or abs(oy) >= half_h:
            raise ConfigError(
                f"{_OWNER}: 'mla_offset_um' {self.mla_offset_um} moves the MLA centre off the sensor "
                f"({2 * half_w:.1f} x {2 * half_h:.1f} um): each offset must be finite and below half the sensor "
                f"(|x| < {half_w:.1f}, |y| < {half_h:.1f} um). An offset is a misalignment, typically below one "
                f"lenslet pitch ({self.mla_pitch_um} um).")
        if self.pmr < 2.0:
            raise ConfigError(
                f"{_OWNER}: the lenslet pitch ({self.mla_pitch_um} um) covers {self.pmr:.3g} pixels of "
                f"{self.pixel_pitch_um} um; a light field needs at least 2 pixels per lenslet. Increase 'mla_pitch_um'."
            )
        sw, sh = w * self.pixel_pitch_um, h * self.pixel_pitch_um
        if self.mla_pitch_um > min(sw, sh):
            raise ConfigError(
                f"{_OWNER}: the lenslet pitch ({self.mla_pitch_um} um) is larger than the sensor "
                f"({sw:.1f} x {sh:.1f} um). Reduce 'mla_pitch_um' or enlarge the sensor."
            )
        if self.mla_count is None:
            nx = int(math.floor((sw - (self.mla_pitch_um / 2 if self.mla_layout == "hex" else 0.0)) / self.mla_pitch_um + 1e-9))
            ny = int(math.floor(sh / self.row_pitch_um + 1e-9))
            self.mla_count = (max(nx, 1), max(ny, 1))
        nx, ny = (int(v) for v in self.mla_count)
        if nx < 1 or ny < 1 or (nx, ny) != tuple(self.mla_count):
            raise ConfigError(f"{_OWNER}: 'mla_count' must be two positive integers, got {self.mla_count!r}.")
        self.mla_count = (nx, ny)
        width = (nx + (0.5 if self.mla_layout == "hex" and ny > 1 else 0.0)) * self.mla_pitch_um
        if width > 1.5 * sw or ny * self.row_pitch_um > 1.5 * sh:
            raise ConfigError(
                f"{_OWNER}: {nx}x{ny} lenslets of {self.mla_pitch_um} um span {width:.0f} x "
                f"{ny * self.row_pitch_um:.0f} um, far larger than the sensor ({sw:.0f} x {sh:.0f} um). "
                f"Reduce 'mla_count' (or leave it out to fill the sensor)."
            )
        self.to_world_mitsuba = np.asarray(self.to_world_mitsuba, dtype=float).reshape(4, 4)
        offs = self.crosstalk_offsets()  # raises for mismatches beyond the model
        self._n_crosstalk = len(offs)

    # ------------------------------------------------------------------ main lens
    @property
    def image_distance_mm(self) -> float:
        """MLA distance behind the main lens, ``s_i``."""
        return float(thin_lens_image_distance(self.focal_length_mm, self.focus_distance_mm))

    @property
    def magnification(self) -> float:
        """Lateral magnification ``|M| = s_i / s_o`` of the focal plane onto the MLA."""
        return self.image_distance_mm / self.focus_distance_mm

    @property
    def aperture_radius_mm(self) -> float:
        return 0.5 * self.aperture_diameter_mm

    @property
    def image_f_number(self) -> float:
        """Image-side (working) f-number ``s_i / D = N (1 + |M|)``."""
        return self.image_distance_mm / self.aperture_diameter_mm

    # ------------------------------------------------------------------ MLA lattice
    @property
    def mla_f_number(self) -> float:
        return self.mla_focal_length_um / self.mla_pitch_um

    @property
    def n_lenslets(self) -> int:
        """Number of lenslets in the array (``mla_count[0] * mla_count[1]``)."""
        return int(self.mla_count[0]) * int(self.mla_count[1])

    @property
    def pmr(self) -> float:
        """Pixels per lenslet pitch (may be non-integer)."""
        return self.mla_pitch_um / self.pixel_pitch_um

    @property
    def row_pitch_um(self) -> float:
        return self.mla_pitch_um * (math.sqrt(3.0) / 2.0 if self.mla_layout == "hex" else 1.0)

    @property
    def gap_mm(self) -> float:
        return self.mla_gap_um * 1e-3

    @property
    def image_scale(self) -> float:
        """``1 + g/s_i``: lenslet-image centres are the lenslet centres scaled by this about the axis."""
        return 1.0 + self.gap_mm / self.image_distance_mm

    @property
    def basis_mm(self) -> np.ndarray:
        """Lattice basis (2, 2) [mm], rows ``a1`` (along a lenslet row) and ``a2`` (next row)."""
        p = self.mla_pitch_um * 1e-3
        a1 = np.array([p, 0.0])
        a2 = np.array([0.5 * p, p * math.sqrt(3.0) / 2.0]) if self.mla_layout == "hex" else np.array([0.0, p])
        th = math.radians(self.mla_rotation_deg)
        rot = np.array([[math.cos(th), -math.sin(th)], [math.sin(th), math.cos(th)]])
        return np.stack([rot @ a1, rot @ a2])

    @property
    def origin_mm(self) -> np.ndarray:
        """Centre of lenslet (column 0, row 0) in the sensor frame [mm]."""
        nx, ny = self.mla_count
        p = self.mla_pitch_um * 1e-3
        x0 = -0.5 * (nx - 1) * p - (0.25 * p if self.mla_layout == "hex" and ny > 1 else 0.0)
        y0 = -0.5 * (ny - 1) * self.row_pitch_um * 1e-3
        th = math.radians(self.mla_rotation_deg)
        rot = np.array([[math.cos(th), -math.sin(th)], [math.sin(th), math.cos(th)]])
        return rot @ np.array([x0, y0]) + np.asarray(self.mla_offset_um) * 1e-3

    def storage_to_axial(self, col, row):
        """Lenslet (column, row) -> lattice coordinates (i, j) along the basis."""
        col, row = np.asarray(col), np.asarray(row)
        if self.mla_layout == "hex":
            return col - row // 2, row  # x = col p + (row % 2) p/2 = (col - row//2) p + row p/2
        return col, row

    def axial_to_storage(self, i, j):
        i, j = np.asarray(i), np.asarray(j)
        if self.mla_layout == "hex":
            return i + j // 2, j
        return i, j

    def lenslet_centres_mm(self) -> np.ndarray:
        """(ny, nx, 2) lenslet centres in the sensor frame [mm] (storage order row, column)."""
        nx, ny = self.mla_count
        row, col = np.mgrid[0:ny, 0:nx]
        i, j = self.storage_to_axial(col, row)
        b = self.basis_mm
        return self.origin_mm + i[..., None] * b[0] + j[..., None] * b[1]

    def image_centres_px(self) -> np.ndarray:
        """(ny, nx, 2) lenslet-image centres in pixel coordinates ``(u, v)``."""
        return self.sensor_mm_to_px(self.lenslet_centres_mm() * self.image_scale)

    def sensor_mm_to_px(self, xy_mm) -> np.ndarray:
        xy = np.asarray(xy_mm, dtype=float)
        w, h = self.resolution
        return xy / (self.pixel_pitch_um * 1e-3) + np.array([w / 2.0, h / 2.0])

    def px_to_sensor_mm(self, uv_px) -> np.ndarray:
        uv = np.asarray(uv_px, dtype=float)
        w, h = self.resolution
        return (uv - np.array([w / 2.0, h / 2.0])) * (self.pixel_pitch_um * 1e-3)

    @property
    def cell_area_mm2(self) -> float:
        return abs(float(np.linalg.det(self.basis_mm)))

    @property
    def cell_circumradius_mm(self) -> float:
        p = self.mla_pitch_um * 1e-3
        return p / math.sqrt(2.0) if self.mla_layout == "rect" else p / math.sqrt(3.0)

    def _cell_polygon(self) -> np.ndarray:
        """Vertices of the Voronoi cell of a lenslet (relative to its centre) [mm]."""
        b = self.basis_mm
        if self.mla_layout == "rect":
            return np.array([0.5 * (sx * b[0] + sy * b[1]) for sx, sy in ((1, 1), (-1, 1), (-1, -1), (1, -1))])
        # Hexagon: circumcentres of the 6 triangles around the origin.
        nbrs = [b[0], b[1], b[1] - b[0], -b[0], -b[1], b[0] - b[1]]
        return np.array([(nbrs[k] + nbrs[(k + 1) % 6]) / 3.0 for k in range(6)])

    @property
    def image_region_radius_mm(self) -> float:
        """Radius of a disk around a lenslet-image centre that holds every sensor point the
        lenslet can light: ``|1 + g/s_i - g/f_m| r_cell + (g/s_i) D/2`` (exact bound for the
        tangent-linear thin lenses)."""
        si, g, fm = self.image_distance_mm, self.gap_mm, self.mla_focal_length_um * 1e-3
        return abs(1.0 + g / si - g / fm) * self.cell_circumradius_mm + (g / si) * self.aperture_radius_mm

    def crosstalk_offsets(self) -> list[tuple[int, int]]:
        """Lattice offsets (di, dj) of the lenslets whose light can reach the pixels that lie
        closest to a given lenslet's image, (0, 0) first.

        The image region of a lenslet is bounded by a disk of radius
        ``|1 + g/s_i - g/f_m| r_cell + (g/s_i) D/2`` around its image centre (exact for the
        tangent-linear thin lenses). More than two rings of neighbours is an f-number
        mismatch beyond the model: raises :class:`ConfigError`.
        """
        rho = self.image_region_radius_mm
        s = self.image_scale
        b = self.basis_mm * s
        poly = self._cell_polygon() * s
        out = [(0, 0)]
        rings = 0
        for di in range(-4, 5):
            for dj in range(-4, 5):
                if (di, dj) == (0, 0):
                    continue
                c = di * b[0] + dj * b[1]
                if _point_polygon_distance(c, poly) < rho:
                    out.append((di, dj))
                    ring = max(abs(di), abs(dj), abs(di + dj)) if self.mla_layout == "hex" else max(abs(di), abs(dj))
                    rings = max(rings, ring)
        if rings > 2:
            raise ConfigError(
                f"{_OWNER}: f-number mismatch beyond the model: the main lens (image-side f/{self.image_f_number:.3g}) "
                f"lights lenslet images {rho / (self.mla_pitch_um * 1e-3 * s):.2f} pitches in radius through "
                f"f/{self.mla_f_number:.3g} lenslets (gap {self.mla_gap_um:.4g} um), reaching {rings} rings of "
                f"neighbours (at most 2 are modelled). Stop the main lens down towards f/"
                f"{self.mla_f_number / (1 + self.magnification):.3g} or use slower lenslets."
            )
        return out

    # ------------------------------------------------------------------ design calculators
    def alpha(self, z_mm):
        """Refocus parameter ``alpha = s_i'/s_i`` of the plane ``z_mm`` beyond the focal plane."""
        return alpha_from_z_geom(z_mm, self.focal_length_mm, self.focus_distance_mm)

    def depth_of_field(self, kind: str = "refocused") -> tuple[float, float]:
        """(near, far) object-space limits [mm, relative to the focal plane, far > 0] of the
        depth of field of a refocused image (``kind="refocused"``: blur on the MLA plane up to
        one lenslet pitch through the full aperture) or of a perspective view
        (``"perspective"``: through one angular sample, ``D / n_u``).
        """
        if kind not in ("refocused", "perspective"):
            raise ConfigError(f"depth_of_field: 'kind' must be 'refocused' or 'perspective', got {kind!r}.")
        nu = max(self.angular_samples, 1.0) if kind == "perspective" else 1.0
        return dof_limits_geom(self.focal_length_mm, self.focus_distance_mm, self.aperture_diameter_mm / nu,
                               self.mla_pitch_um * 1e-3)

    def depth_resolution(self) -> float:
        """Smallest depth step [mm] between distinguishable refocus planes at the focal plane:
        the depth change that moves a point's image by one lenslet pitch between the two
        outermost angular samples (``n_u - 1`` samples apart across the aperture)."""
        return depth_resolution_geom(self.focal_length_mm, self.focus_distance_mm, self.aperture_diameter_mm,
                                     self.mla_pitch_um * 1e-3, self.angular_samples)

    @property
    def angular_samples(self) -> float:
        """Angular samples across the aperture image: the pixels spanned by the lenslet image
        of the aperture, ``D g / (s_i p_px)`` (equals the PMR at f-number matching)."""
        return self.aperture_diameter_mm * self.gap_mm / self.image_distance_mm / (self.pixel_pitch_um * 1e-3)

    def lateral_resolution_mm(self) -> float:
        """Object-space size of one lenslet at the focal plane (the refocused pixel)."""
        return self.mla_pitch_um * 1e-3 / self.magnification

    def pixel_budget(self, particles_per_lenslet: float | None = None) -> dict:
        """LF-PIV pixel bookkeeping: MLA resolution, pixels per lenslet, and the seeding
        conversion ``ppp = ppm / (pixels per lenslet)`` (particles per pixel of the raw
        image vs per microlens), and the light-field-to-tomographic pixel ratio (raw pixels
        per refocused pixel)."""
        nx, ny = self.mla_count
        px_per_lenslet = self.cell_area_mm2 / (self.pixel_pitch_um * 1e-3) ** 2
        out = {
            "mla_resolution": [nx, ny],
            "lenslets": nx * ny,
            "pixels_per_lenslet_pitch": self.pmr,
            "pixels_per_lenslet_area": px_per_lenslet,
            "angular_samples": self.angular_samples,
            "lf_to_tomo_pixel_ratio": self.resolution[0] * self.resolution[1] / (nx * ny),
        }
        if particles_per_lenslet is not None:
            out["ppm"] = float(particles_per_lenslet)
            out["ppp"] = float(particles_per_lenslet) / px_per_lenslet
        return out

    # ------------------------------------------------------------------ metadata
    def to_dict(self) -> dict:
        nx, ny = self.mla_count
        return {
            "model": "plenoptic_1.0_thin_lens",
            "convention": "camera-local Mitsuba frame (x left, y up, z forward), main lens at z=0, MLA at "
            "z=-image_distance_mm, sensor at z=-(image_distance_mm+gap); sensor frame X=(u-W/2)*pitch, "
            "Y=(v-H/2)*pitch; pixel (i, j) spans [i, i+1)",
            "resolution": list(self.resolution),
            "pixel_pitch_um": self.pixel_pitch_um,
            "focal_length_mm": self.focal_length_mm,
            "f_number": self.f_number,
            "aperture_diameter_mm": self.aperture_diameter_mm,
            "focus_distance_mm": self.focus_distance_mm,
            "image_distance_mm": self.image_distance_mm,
            "magnification": self.magnification,
            "image_f_number": self.image_f_number,
            "mla_pitch_um": self.mla_pitch_um,
            "mla_focal_length_um": self.mla_focal_length_um,
            "mla_f_number": self.mla_f_number,
            "mla_layout": self.mla_layout,
            "mla_count": [nx, ny],
            "mla_rotation_deg": self.mla_rotation_deg,
            "mla_offset_um": list(self.mla_offset_um),
            "mla_gap_um": self.mla_gap_um,
            "pmr": self.pmr,
            "image_scale": self.image_scale,
            "lattice_basis_mm": self.basis_mm.tolist(),
            "lattice_origin_mm": self.origin_mm.tolist(),
            "crosstalk_offsets": [list(o) for o in self.crosstalk_offsets()],
            "to_world_mitsuba": self.to_world_mitsuba.tolist(),
            "distortion": self.distortion.to_dict(),
        }

    @classmethod
    def from_dict(cls, d: dict) -> PlenopticCamera:
        return cls(
            resolution=tuple(d["resolution"]), pixel_pitch_um=d["pixel_pitch_um"], focal_length_mm=d["focal_length_mm"],
            focus_distance_mm=d["focus_distance_mm"], mla_pitch_um=d["mla_pitch_um"],
            aperture_diameter_mm=d["aperture_diameter_mm"], mla_focal_length_um=d["mla_focal_length_um"],
            mla_layout=d["mla_layout"], mla_count=tuple(d["mla_count"]), mla_rotation_deg=d["mla_rotation_deg"],
            mla_offset_um=tuple(d["mla_offset_um"]), mla_gap_um=d["mla_gap_um"],
            to_world_mitsuba=np.asarray(d["to_world_mitsuba"]),
            distortion=Distortion(**d.get("distortion", {})),
        )

    # ------------------------------------------------------------------ rays (float64)
    def nearest_lenslet(self, xy_mm) -> tuple[np.ndarray, np.ndarray]:
        """Axial lattice indices (i, j) of the lenslet whose cell holds MLA-plane points (..., 2) [mm]."""
        xy = np.asarray(xy_mm, dtype=float)
        f = (xy - self.origin_mm) @ np.linalg.inv(self.basis_mm)
        if self.mla_layout == "rect":
            return np.floor(f[..., 0] + 0.5).astype(np.int64), np.floor(f[..., 1] + 0.5).astype(np.int64)
        i0, j0 = np.floor(f[..., 0]).astype(np.int64), np.floor(f[..., 1]).astype(np.int64)
        best = np.full(xy.shape[:-1], np.inf)
        bi, bj = i0.copy(), j0.copy()
        for di, dj in ((0, 0), (1, 0), (0, 1), (1, 1)):
            c = self.origin_mm + (i0 + di)[..., None] * self.basis_mm[0] + (j0 + dj)[..., None] * self.basis_mm[1]
            d = np.sum((xy - c) ** 2, axis=-1)
            better = d < best
            bi, bj, best = np.where(better, i0 + di, bi), np.where(better, j0 + dj, bj), np.where(better, d, best)
        return bi, bj

    def lenslet_exists(self, i, j) -> np.ndarray:
        col, row = self.axial_to_storage(i, j)
        return (col >= 0) & (col < self.mla_count[0]) & (row >= 0) & (row < self.mla_count[1])

    def image_side_tangents(self, p_local_mm, lens_xy_mm) -> np.ndarray:
        """Image-side tangents (..., 2) of rays from camera-local points (..., 3) through
        main-lens points (..., 2) [mm]: the thin lens ``t -> t - a/f`` applied to the
        (distorted, see ``distortion``) tangent of the ray into the camera. A ray crosses
        the plane ``s`` behind the lens at ``a + s t`` (the MLA at ``s_i``, a refocus plane
        at ``alpha s_i``)."""
        p = np.asarray(p_local_mm, dtype=float)
        a = np.asarray(lens_xy_mm, dtype=float)
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = (a - p[..., :2]) / p[..., 2:3]  # tangent per unit distance travelled into the camera
        if not self.distortion.is_zero:  # the lens refracts the distorted object-side tangent
            tx, ty = distort(-t1[..., 0], -t1[..., 1], self.distortion)
            t1 = -np.stack([tx, ty], axis=-1)
        return t1 - a / self.focal_length_mm

    def trace_to_sensor(self, p_local_mm, lens_xy_mm) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Light rays from camera-local points through main-lens points to the sensor (float64).

        The forward (light-tracing) counterpart of :meth:`camera_rays`, the path of a
        particle's light ray in the ``plenoptic`` sensor, without crosstalk rejection:
        point ``P`` -> main-lens point ``a`` (thin lens, tangent ``t -> t - a/f``) -> MLA
        plane at ``s_i`` -> the lenslet whose cell holds the ray (thin lens centred on
        ``c``, ``t -> t - (x - c)/f_m``: the paper's refraction plus prism, its eq. 3) ->
        sensor at ``g``. Tangents, not angles: exact for ideal thin lenses; the paraxial
        ray-transfer matrices of Fahringer & Thurow (eqs. 1-4), which use angles, agree to
        ``O(theta^3)`` (tests/physics/test_plenoptic_paper_optics.py).

        Parameters
        ----------
        p_local_mm : (..., 3)
            Source points in the camera-local frame (lens at the origin, ``z > 0`` in front).
        lens_xy_mm : (..., 2)
            Points on the main-lens plane the rays pass through.

        Returns
        -------
        sensor_xy_mm (..., 2) in the sensor frame, lenslet (..., 2) int axial indices (i, j),
        valid (...) bool: inside the aperture, in front of the lens, and the lenslet exists.
        """
        p = np.asarray(p_local_mm, dtype=float)
        a = np.asarray(lens_xy_mm, dtype=float)
        si, g = self.image_distance_mm, self.gap_mm
        fm = self.mla_focal_length_um * 1e-3
        t2 = self.image_side_tangents(p, a)
        xm = a + si * t2
        i, j = self.nearest_lenslet(xm)
        b = self.basis_mm
        c = self.origin_mm + i[..., None] * b[0] + j[..., None] * b[1]
        t3 = t2 - (xm - c) / fm
        xs = xm + g * t3
        valid = (np.sum(a * a, axis=-1) <= self.aperture_radius_mm**2) & (p[..., 2] > 0) & self.lenslet_exists(i, j)
        return xs, np.stack([i, j], axis=-1), valid

    def camera_rays(self, uv_px, cell_uv) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """World rays of sensor points through points of their own lenslet (float64).

        The NumPy counterpart of the ``plenoptic`` sensor's camera path, without crosstalk:
        sensor point ``P`` (pixel coordinates ``uv_px``) -> the lenslet whose image holds it
        -> the lenslet point ``c + d``, ``d`` the cell point ``cell_uv`` in [0, 1)^2 of the
        lattice parallelogram (folded onto the hexagonal cell) -> main lens.

        Returns
        -------
        origins (..., 3) on the main lens [mm, world], unit directions (..., 3) [world],
        valid (...) bool: the lenslet exists and the ray passes the aperture.
        """
        uv = np.asarray(uv_px, dtype=float)
        cu = np.asarray(cell_uv, dtype=float)
        p = self.px_to_sensor_mm(uv)
        i, j = self.nearest_lenslet(p / self.image_scale)
        b = self.basis_mm
        c = self.origin_mm + i[..., None] * b[0] + j[..., None] * b[1]
        d = (cu[..., 0:1] - 0.5) * b[0] + (cu[..., 1:2] - 0.5) * b[1]
        if self.mla_layout == "hex":  # fold the parallelogram onto the hexagonal cell
            ni, nj = self.nearest_lenslet(c + d)
            d = d - (ni - i)[..., None] * b[0] - (nj - j)[..., None] * b[1]
        g, fm, si, f = self.gap_mm, self.mla_focal_length_um * 1e-3, self.image_distance_mm, self.focal_length_mm
        t2 = (c + d - p) / g - d / fm
        lens = c + d + si * t2
        inside = np.sum(lens * lens, axis=-1) <= self.aperture_radius_mm**2
        t3 = t2 - lens / f
        if not self.distortion.is_zero:  # object-side tangent whose distorted image is t3
            tx, ty = undistort(t3[..., 0], t3[..., 1], self.distortion, iterations=12)
            t3 = np.stack([tx, ty], axis=-1)
        m = self.to_world_mitsuba
        origins = m[:3, 3] + np.concatenate([lens, np.zeros(lens.shape[:-1] + (1,))], axis=-1) @ m[:3, :3].T
        dirs = np.concatenate([t3, np.ones(t3.shape[:-1] + (1,))], axis=-1) @ m[:3, :3].T
        dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
        return origins, dirs, self.lenslet_exists(i, j) & inside

    # ------------------------------------------------------------------ pose
    def world_to_local(self, p_world) -> np.ndarray:
        """World points (..., 3) -> camera-local (Mitsuba frame, lens at the origin)."""
        m = self.to_world_mitsuba
        return (np.asarray(p_world, dtype=float) - m[:3, 3]) @ m[:3, :3]

    # ------------------------------------------------------------------ camera contract
    @property
    def chief_ray_scale_px(self) -> float:
        """``(s_i + g) / p_px``: pixels per unit of ``-(x, y)/z`` on the sensor (the focal
        length, in pixels, of the equivalent pinhole of :meth:`project`)."""
        return self.image_distance_mm * self.image_scale / (self.pixel_pitch_um * 1e-3)

    def project(self, p_world_mm) -> np.ndarray:
        """Image point of world points (..., 3) [mm] in pixel coordinates (..., 2).

        The chief ray through the main-lens centre meets the MLA plane at
        ``X = -s_i (x, y) / z`` (camera-local Mitsuba frame); scaled by ``1 + g/s_i``, as the
        lenslet-image centres are, it gives the sensor point ``(s_i + g) (-(x, y) / z)``
        round which the point's light gathers on the lenslet-image lattice (the point's
        image in a refocused or sub-aperture view). A point behind the lens projects
        mirrored (see :meth:`visible`).
        """
        q = self.world_to_local(p_world_mm)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = -q[..., :2] / q[..., 2:3]
        if not self.distortion.is_zero:  # the chief ray's tangent through the distorting lens
            tx, ty = distort(t[..., 0], t[..., 1], self.distortion)
            t = np.stack([tx, ty], axis=-1)
        w, h = self.resolution
        return t * self.chief_ray_scale_px + np.array([w / 2.0, h / 2.0])

    def pixel_to_ray(self, uv_px, *, iterations: int = 20):
        """Chief rays through the main-lens centre of image points, the inverse of
        :meth:`project`: (origin (3,), unit directions (..., 3)) in world."""
        uv = np.asarray(uv_px, dtype=float)
        w, h = self.resolution
        t = (uv - np.array([w / 2.0, h / 2.0])) / self.chief_ray_scale_px
        if not self.distortion.is_zero:
            tx, ty = undistort(t[..., 0], t[..., 1], self.distortion, iterations=iterations)
            t = np.stack([tx, ty], axis=-1)
        d = np.concatenate([-t, np.ones(t.shape[:-1] + (1,))], axis=-1)  # project: t = -(x, y) / z
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
        m = self.to_world_mitsuba
        return m[:3, 3].copy(), d @ m[:3, :3].T

    def in_front(self, p_world_mm) -> np.ndarray:
        """Points (..., 3) [mm] in front of the main lens (local z > 0), shape (...)."""
        return self.world_to_local(p_world_mm)[..., 2] > 0

    def visible(self, p_world_mm) -> np.ndarray:
        """Points (..., 3) [mm] in front of the main lens whose image point
        (:meth:`project`) lands on the sensor ``[0, W) x [0, H)``, shape (...); with a
        distorting main lens also inside the radial map's invertible branch
        (:func:`~mitpiv.physics.distortion.fold_radius`)."""
        with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
            ok = self.in_front(p_world_mm) & on_sensor(self.project(p_world_mm), self.resolution)
            if not self.distortion.is_zero:
                q = self.world_to_local(p_world_mm)
                ok &= np.hypot(q[..., 0], q[..., 1]) / q[..., 2] < fold_radius(self.distortion)
            return ok

    def jacobian(self, p_world_mm) -> np.ndarray:
        """``d(u, v)/d(x, y, z)`` of :meth:`project`, shape (..., 2, 3) [px/mm] (analytic)."""
        q = self.world_to_local(p_world_mm)
        z = q[..., 2]
        k = self.chief_ray_scale_px
        d = np.zeros(q.shape[:-1] + (2, 3))
        d[..., 0, 0] = -k / z
        d[..., 0, 2] = k * q[..., 0] / (z * z)
        d[..., 1, 1] = -k / z
        d[..., 1, 2] = k * q[..., 1] / (z * z)
        if not self.distortion.is_zero:  # radial map of t = -(x, y)/z: chain rule
            with np.errstate(divide="ignore", invalid="ignore"):
                _, _, ja, jb, jc, je = distort_jacobian(-q[..., 0] / z, -q[..., 1] / z, self.distortion)
            jac = np.stack([np.stack([ja, jb], -1), np.stack([jc, je], -1)], -2)
            d = jac @ d
        # q = (p - t) R  ->  dq/dp = R^T
        return d @ self.to_world_mitsuba[:3, :3].T


# ---------------------------------------------------------------------- helpers
def _point_polygon_distance(p, poly) -> float:
    """Distance from point ``p`` to a convex polygon (0 inside)."""
    n = len(poly)
    inside = True
    best = np.inf
    for k in range(n):
        a, b = poly[k], poly[(k + 1) % n]
        e = b - a
        cross = e[0] * (p[1] - a[1]) - e[1] * (p[0] - a[0])
        if cross < 0:
            inside = False
        t = np.clip((p - a) @ e / (e @ e), 0.0, 1.0)
        best = min(best, float(np.linalg.norm(p - (a + t * e))))
    # Vertices are counter-clockwise for both layouts; a point inside has every cross >= 0.
    return 0.0 if inside else best


def alpha_from_z_geom(z_mm, focal_length_mm: float, focus_distance_mm: float):
    """Refocus parameter ``alpha = s_i(s_o + z) / s_i(s_o)`` of the plane ``z_mm`` beyond the
    focal plane, by the thin-lens equation (Ng 2005; ``z > 0`` farther from the camera,
    ``alpha < 1`` there). The one place this formula is written: :meth:`PlenopticCamera.alpha`
    and :func:`mitpiv.lightfield.alpha_from_z` call it.

    Parameters
    ----------
    z_mm : float or array
        Depth from the focal plane [mm], finite and ``> f - s_o``.
    focal_length_mm : float
        Main-lens focal length ``f`` [mm].
    focus_distance_mm : float
        Object distance of the focal plane ``s_o`` [mm] (``> f``).

    Returns
    -------
    ndarray (shape of ``z_mm``)
    """
    f, so0 = float(focal_length_mm), float(focus_distance_mm)
    z = np.asarray(z_mm, dtype=float)
    so = so0 + z
    finite = np.isfinite(z)
    if not np.all(finite) or np.any(so <= f * (1 + 1e-9)):
        got = "a non-finite z" if not np.all(finite) else f"min z = {np.min(z):.6g}"
        raise ConfigError(
            f"alpha_from_z: every z must be finite and > {f - so0:.6g} mm (the object must stay beyond the focal "
            f"length, {f} mm from the lens; the focal plane is at {so0:.6g} mm); got {got}."
        )
    return thin_lens_image_distance(f, so) / thin_lens_image_distance(f, so0)


def dof_limits_geom(f, so, aperture, blur) -> tuple[float, float]:
    """Object-space (near, far) offsets [mm from the focal plane] where the blur spot on the
    MLA plane (at ``s_i`` of the focal plane ``so``) through an ``aperture`` [mm] wide lens of
    focal length ``f`` [mm] reaches ``blur`` [mm] (Deem et al. 2016's construction)."""
    si = float(thin_lens_image_distance(f, so))
    # Blur on the plane at si from an image at si': aperture |si - si'| / si' = blur.
    si_far = si * aperture / (aperture + blur)  # image closer to the lens -> object farther
    si_near = si * aperture / (aperture - blur) if aperture > blur else np.inf
    so_far = f * si_far / (si_far - f) if si_far > f else np.inf
    so_near = f * si_near / (si_near - f) if np.isfinite(si_near) else f
    return float(so_near - so), float(so_far - so)


def depth_resolution_geom(f, so, aperture, pitch, n_u) -> float:
    """Depth step [mm] that shifts a point's image by one lenslet pitch between the
    outermost angular samples (baseline ``aperture (n_u - 1) / n_u``), at the focal plane."""
    si = float(thin_lens_image_distance(f, so))
    base = aperture * max(n_u - 1.0, 1.0) / max(n_u, 1.0)
    dsi = pitch * si / base  # image-side shift of the refocus plane
    m = si / so
    return float(dsi / (m * m))


_dof_limits = dof_limits_geom  # deprecated private name


def ltpr(lf_resolution_px, tomo_resolution_px, n_cameras: int) -> float:
    """Light-field-camera to tomographic-cameras pixel ratio (Shi et al., 'A detailed comparison
    of single-camera light-field PIV and tomographic PIV', section 2):

    ::

        LTPR = (p_x p_y)_LF-PIV / (p_x p_y N_c)_Tomo-PIV

    Parameters
    ----------
    lf_resolution_px : (p_x, p_y) of the light-field camera [px]
    tomo_resolution_px : (p_x, p_y) of each tomographic camera [px]
    n_cameras : N_c, the tomographic cameras (>= 1)
    """
    lf = np.broadcast_to(np.asarray(lf_resolution_px, dtype=float), (2,))
    tomo = np.broadcast_to(np.asarray(tomo_resolution_px, dtype=float), (2,))
    if not (np.all(lf > 0) and np.all(tomo > 0)):
        raise ConfigError(f"ltpr: resolutions must be positive, got {lf.tolist()} and {tomo.tolist()} px.")
    if isinstance(n_cameras, bool) or int(n_cameras) != n_cameras or n_cameras < 1:
        raise ConfigError(f"ltpr: 'n_cameras' must be an integer >= 1, got {n_cameras!r}.")
    return float(lf[0] * lf[1] / (tomo[0] * tomo[1] * int(n_cameras)))
