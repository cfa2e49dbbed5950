"""Decoding a raw plenoptic image into a 4D light field ``L[s, t, u, v]``.

``(s, t)``: spatial samples on an axis-aligned grid over the lenslet lattice (one sample
per lenslet along a row, one per row; a hex or rotated lattice is resampled onto it by
barycentric / bilinear interpolation between lenslets). ``(u, v)``: angular samples, the
pixel offsets ``du`` from each lenslet-image centre, i.e. main-lens aperture points
``a = -du p_px s_i / g`` (see :mod:`mitpiv.physics.plenoptic`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy import ndimage

from mitpiv.errors import ConfigError
from mitpiv.lightfield.calibration import MLACalibration, calibration_from_camera
from mitpiv.physics.plenoptic import PlenopticCamera

__all__ = ["LightField", "decode", "INTERPOLATION"]

INTERPOLATION = {"nearest": 0, "linear": 1, "cubic": 3}


@dataclass
class LightField:
    """A decoded light field.

    Attributes
    ----------
    data : (n_v, n_u, n_t, n_s) float32
        Sub-aperture images, view-major (``data[iv, iu]`` is an image, rows = t).
    s_px, t_px : (n_s,), (n_t,)
        Spatial grid in raw-pixel coordinates of the lenslet-image lattice.
    du_px : (n_u,)
        Angular offsets [px] from the lenslet-image centres (same for v).
    view_weights : (n_v, n_u)
        Relative light collected by each view (from the white image, or the aperture
        geometry), the weights of multiplicative refocusing; 0 = unusable view.
    valid : (n_t, n_s) bool
        Spatial samples inside the lenslet lattice.
    optics : PlenopticCamera or None
        The camera model (needed for metric geometry: alpha <-> z, world grids).
    """

    data: np.ndarray
    s_px: np.ndarray
    t_px: np.ndarray
    du_px: np.ndarray
    view_weights: np.ndarray
    valid: np.ndarray
    optics: PlenopticCamera | None = None
    info: dict = field(default_factory=dict)

    @property
    def L(self) -> np.ndarray:
        """The light field indexed ``L[s, t, u, v]`` (a transposed view of :attr:`data`)."""
        return self.data.transpose(3, 2, 1, 0)

    @property
    def shape(self) -> tuple[int, int, int, int]:
        return self.L.shape

    def view(self, iu: int, iv: int) -> np.ndarray:
        """Sub-aperture (perspective) image of angular sample (iu, iv), rows = t."""
        return self.data[iv, iu]

    def mosaic(self) -> np.ndarray:
        """Sub-aperture images tiled in (v, u) order: (n_v n_t, n_u n_s)."""
        nv, nu, nt, ns = self.data.shape
        return self.data.transpose(0, 2, 1, 3).reshape(nv * nt, nu * ns)

    def save(self, path) -> Path:
        """Write the light field to a ``.npz`` file (atomic); see :func:`mitpiv.io.write_lightfield`."""
        from mitpiv.io.lightfield import write_lightfield

        return write_lightfield(path, self)

    @classmethod
    def load(cls, path) -> LightField:
        """Read a light field written by :meth:`save`; see :func:`mitpiv.io.read_lightfield`."""
        from mitpiv.io.lightfield import read_lightfield

        return cls(**read_lightfield(path))

    def _need_optics(self, what: str) -> PlenopticCamera:
        if self.optics is None:
            raise ConfigError(f"{what} needs the camera optics: decode with optics=PlenopticCamera(...) or from EXR metadata.")
        return self.optics

    @property
    def s_mm(self) -> np.ndarray:
        """Spatial grid on the MLA plane [mm, sensor frame] (lenslet-image lattice / (1 + g/s_i))."""
        o = self._need_optics("s_mm")
        return o.px_to_sensor_mm(np.column_stack([self.s_px, np.zeros_like(self.s_px)]))[:, 0] / o.image_scale

    @property
    def t_mm(self) -> np.ndarray:
        o = self._need_optics("t_mm")
        return o.px_to_sensor_mm(np.column_stack([np.zeros_like(self.t_px), self.t_px]))[:, 1] / o.image_scale

    @property
    def aperture_mm(self) -> np.ndarray:
        """Main-lens aperture coordinate [mm] of each angular sample, ``-du p_px s_i / g``."""
        o = self._need_optics("aperture_mm")
        return -self.du_px * (o.pixel_pitch_um * 1e-3) * o.image_distance_mm / o.gap_mm


def _read_input(raw):
    meta = {}
    if isinstance(raw, (str, Path)):
        from mitpiv.io import read_exr

        raw, meta = read_exr(raw)
    img = np.asarray(raw, dtype=np.float32)
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[..., 0]
    if img.ndim != 2:
        raise ConfigError(f"decode: the raw image must be 2D, got shape {img.shape}.")
    if not np.all(np.isfinite(img)):
        raise ConfigError("decode: the raw image contains NaN or infinite values.")
    return img, meta


def optics_from_metadata(meta: dict) -> PlenopticCamera | None:
    cam = (meta or {}).get("camera")
    if isinstance(cam, dict) and cam.get("type") == "plenoptic":
        return PlenopticCamera.from_dict(cam)
    return None


def _sample_lenslets(img, centres, du, order):
    """Raw values at every lenslet-image centre + (du_u, du_v): (N, n_v, n_u)."""
    n = len(du)
    x = centres[:, None, None, 0] + du[None, None, :] - 0.5
    y = centres[:, None, None, 1] + du[None, :, None] - 0.5
    x = np.broadcast_to(x, (len(centres), n, n))
    y = np.broadcast_to(y, (len(centres), n, n))
    if order == 0:  # nearest pixel, exact and cheap
        xi = np.clip(np.floor(x + 0.5).astype(np.int64), -1, img.shape[1])
        yi = np.clip(np.floor(y + 0.5).astype(np.int64), -1, img.shape[0])
        ok = (xi >= 0) & (xi < img.shape[1]) & (yi >= 0) & (yi < img.shape[0])
        return np.where(ok, img[np.clip(yi, 0, img.shape[0] - 1), np.clip(xi, 0, img.shape[1] - 1)], 0.0).astype(np.float32)
    out = ndimage.map_coordinates(img, [y.ravel(), x.ravel()], order=order, mode="constant", cval=0.0,
                                  prefilter=order > 1).reshape(x.shape)
    if order > 1:
        # a cubic spline overshoots below 0 beside a bright lenslet image's edge: light is not negative
        np.maximum(out, 0.0, out=out)
    return out.astype(np.float32)


def _grid_weights(cal: MLACalibration, s_px, t_px):
    """Lattice interpolation of the grid points: (n_t*n_s, k) lenslet indices and weights."""
    xx, yy = np.meshgrid(s_px, t_px)
    pts = np.column_stack([xx.ravel(), yy.ravel()])
    f = np.linalg.solve(cal.basis_px.T, (pts - cal.origin_px).T).T
    i0 = np.floor(f[:, 0]).astype(np.int64)
    j0 = np.floor(f[:, 1]).astype(np.int64)
    r, s = f[:, 0] - i0, f[:, 1] - j0
    if cal.layout == "rect":
        corners = [(0, 0), (1, 0), (0, 1), (1, 1)]
        w = np.stack([(1 - r) * (1 - s), r * (1 - s), (1 - r) * s, r * s], axis=1)
    else:  # barycentric in the triangle of the hex lattice that holds the point
        upper = r + s > 1
        corners = [(0, 0), (1, 0), (0, 1), (1, 1)]
        w = np.stack([np.where(upper, 0, 1 - r - s), np.where(upper, 1 - s, r), np.where(upper, 1 - r, s),
                      np.where(upper, r + s - 1, 0)], axis=1)
    lo = cal.axial.min(0)
    table = -np.ones(tuple(cal.axial.max(0) - lo + 1), np.int64)
    table[cal.axial[:, 0] - lo[0], cal.axial[:, 1] - lo[1]] = np.arange(len(cal.axial))
    idx = np.empty((len(pts), 4), np.int64)
    for k, (di, dj) in enumerate(corners):
        ii, jj = i0 + di - lo[0], j0 + dj - lo[1]
        ok = (ii >= 0) & (ii < table.shape[0]) & (jj >= 0) & (jj < table.shape[1])
        idx[:, k] = np.where(ok, table[np.clip(ii, 0, table.shape[0] - 1), np.clip(jj, 0, table.shape[1] - 1)], -1)
    w = np.where(np.abs(w) < 1e-9, 0.0, w)
    valid = np.all((idx >= 0) | (w == 0), axis=1)
    w = np.where(valid[:, None], w, 0.0)
    return idx, w.astype(np.float32), valid


def decode(raw, calibration: MLACalibration | None = None, *, white=None, interpolation: str = "linear",
           angular_oversample: int = 1, optics: PlenopticCamera | None = None,
           white_threshold: float = 0.05, min_view_weight: float = 0.1, spatial_oversample: int = 1) -> LightField:
    """Decode a raw plenoptic image.

    Parameters
    ----------
    raw : (H, W) array or path to an EXR rendered by mitpiv
        The raw image; an EXR carries the camera model in its metadata.
    calibration : MLACalibration, optional
        From :func:`calibrate_mla` (a real camera's white image); default: the exact
        lattice of the camera model.
    white : (H, W) array or path, optional
        White image: divides the light field (devignetting) and gives the view weights.
    interpolation : "nearest" | "linear" | "cubic"
        Sampling of the raw image at the (sub-pixel) angular sample positions (cubic: a
        spline, its undershoots below zero beside bright edges clipped to 0).
    angular_oversample : int
        Angular samples per pixel (1: one per pixel across the lenslet image).
    optics : PlenopticCamera, optional
        Camera model, when the raw image carries none.
    white_threshold : float
        Light-field samples where the white light field is below this fraction of its
        maximum are set to zero (no light reaches them).
    min_view_weight : float
        With a white image: views collecting less than this fraction of the best view's
        light get weight 0 (left out of refocusing).
    spatial_oversample : int
        Spatial samples per lenslet pitch along each axis (1: one per lenslet row pitch and
        column pitch). 2 resamples the lattice onto a grid twice as fine, about 4 output
        pixels per lenslet, as LFIT's supersampling does (seed paper 003, ch. II: "approximately
        4 output image pixels per microlens"); the samples between lenslets are
        interpolated, so the resolution does not improve. Memory and refocusing time grow
        as its square.
    """
    if interpolation not in INTERPOLATION:
        raise ConfigError(f"decode: 'interpolation' must be one of {sorted(INTERPOLATION)}, got {interpolation!r}.")
    if int(angular_oversample) != angular_oversample or not 1 <= angular_oversample <= 8:
        raise ConfigError(f"decode: 'angular_oversample' must be an integer in 1..8, got {angular_oversample!r}.")
    img, meta = _read_input(raw)
    optics = optics or optics_from_metadata(meta)
    if optics is not None and tuple(optics.resolution) != (img.shape[1], img.shape[0]):
        raise ConfigError(f"decode: the raw image is {img.shape[1]}x{img.shape[0]} but the camera model has "
                          f"{optics.resolution[0]}x{optics.resolution[1]} pixels.")
    if calibration is None:
        if optics is None:
            raise ConfigError("decode: give a 'calibration' (calibrate_mla on a white image) or a camera model "
                              "('optics', or an EXR with plenoptic metadata).")
        calibration = calibration_from_camera(optics)
    if isinstance(spatial_oversample, bool) or int(spatial_oversample) != spatial_oversample or not 1 <= spatial_oversample <= 4:
        raise ConfigError(f"decode: 'spatial_oversample' must be an integer in 1..4, got {spatial_oversample!r}.")
    cal = calibration
    pitch = cal.pitch_px
    n = max(int(math.floor(pitch * angular_oversample + 1e-9)), 1)
    du = ((np.arange(n) - (n - 1) / 2.0) / angular_oversample).astype(np.float64)
    row = pitch * (math.sqrt(3.0) / 2.0 if cal.layout == "hex" else 1.0)
    lo, hi = cal.centres_px.min(0), cal.centres_px.max(0)
    o = cal.origin_px
    sp, rp = pitch / int(spatial_oversample), row / int(spatial_oversample)
    s_px = o[0] + sp * np.arange(math.ceil((lo[0] - o[0]) / sp - 1e-9), math.floor((hi[0] - o[0]) / sp + 1e-9) + 1)
    t_px = o[1] + rp * np.arange(math.ceil((lo[1] - o[1]) / rp - 1e-9), math.floor((hi[1] - o[1]) / rp + 1e-9) + 1)
    idx, w, valid = _grid_weights(cal, s_px, t_px)
    valid = valid.reshape(len(t_px), len(s_px))
    order = INTERPOLATION[interpolation]

    def to_grid(image):
        lk = _sample_lenslets(image, cal.centres_px, du, order).reshape(len(cal.centres_px), -1)
        out = np.zeros((len(idx), lk.shape[1]), np.float32)
        for k in range(4):
            wk = w[:, k]
            m = wk != 0
            out[m] += wk[m, None] * lk[idx[m, k]]
        return np.ascontiguousarray(out.reshape(len(t_px), len(s_px), n, n).transpose(2, 3, 0, 1))

    data = to_grid(img)
    if white is not None:
        wimg, _ = _read_input(white)
        if wimg.shape != img.shape:
            raise ConfigError(f"decode: the white image ({wimg.shape}) and the raw image ({img.shape}) differ in size.")
        wlf = to_grid(wimg)
        top = float(wlf.max())
        if top <= 0:
            raise ConfigError("decode: the white image is all dark; it cannot devignette.")
        lit = wlf > white_threshold * top
        data = np.where(lit, data / np.where(lit, wlf, 1.0), 0.0).astype(np.float32)
        vw = (wlf * valid[None, None]).sum(axis=(2, 3))
        weights = vw / vw.max()
        weights[weights < min_view_weight] = 0.0  # views at the rim of the aperture image: too little light to trust
    elif optics is not None:
        r_img = optics.aperture_radius_mm * optics.gap_mm / optics.image_distance_mm / (optics.pixel_pitch_um * 1e-3)
        weights = (np.hypot(du[None, :], du[:, None]) <= r_img).astype(np.float64)
    else:
        weights = np.ones((n, n))
    info = {"interpolation": interpolation, "angular_oversample": int(angular_oversample),
            "spatial_oversample": int(spatial_oversample),
            "calibration": cal.to_dict(), "devignetted": white is not None}
    return LightField(data, s_px, t_px, du, weights.astype(np.float64), valid, optics, info)
