"""Measures and calibration of the plenoptic vs digital in-line holography comparison of
drop-impact fragments and shotgun pellets (seed paper 003, chapters IV-VI).

* The dot-card dewarp (ch. V.A): a dot card (1 mm dots at 3 mm pitch) imaged at 25 depths,
  every 2.5 mm over +-30 mm about the focal plane; each dot's location in the focal stack
  (its refocus-plane position and refocus parameter ``alpha``) is related to its known
  object-space position by "a 3D second order polynomial fit" solved by "matrix
  inversion" (least squares): :func:`fit_stack_dewarp`, :class:`StackDewarp`. The paper
  does not list the monomials; "second order in 3D" is taken as every monomial of total
  degree <= 2 in (u, v, alpha) (10 terms per output coordinate).
  :func:`dot_card_observations` gives the dots' stack locations through a
  :class:`~mitpiv.physics.plenoptic.PlenopticCamera` (its distorting main lens included)
  from the ray bundle of each dot centre: the plane behind the lens where the bundle is
  narrowest (``alpha = s / s_i``) and the bundle's centroid there (the dot's centre in the
  refocused image on that plane, Ng's eq. 9 coordinates), or the same location in
  nominal object-space millimetres (eq. 11 for depth). Which of the two the paper's
  polynomial took is not stated; the choice matters: over alpha 0.914-1.139 the depth of
  eq. 11 is far from quadratic in alpha, so a second-order fit in (u, v, alpha) leaves
  ~0.29 mm RMS in z even for an ideal lens, while in nominal millimetres the ideal lens is
  the identity and the polynomial only absorbs the distortion.
* Focal stacks: :func:`paper_alphas` (N planes between the paper's alpha limits, eq. 11).
* Model error (ch. VI.A.1, Fig. 25, Table 2): the displacement component minus the linear
  fit of that component against the distance from the impact centre, evaluated at the
  measured position; its standard deviation per component (:func:`model_error`), and the
  z positional uncertainty as the difference of the z and x standard deviations
  (:func:`z_uncertainty`, which reproduces every row of Table 2).
* The flow's scatter as an input (:func:`velocity_sd_for_model_error`): the film-plane
  velocity scatter of :func:`mitpiv.physics.drop_impact.fragment_field` whose true field
  (every fragment, no imaging) gives a stated model error. The scatter put in is not the
  model error read out: a ballistic fragment's position carries its velocity perturbation,
  so the linear fit absorbs part of it (a factor 1.25-1.52 over Table 2's conditions).
* The fragment-size power law ``d/d0 = q tau^n`` (Figs. 28-29): :func:`power_law_fit`
  (least squares on the logarithms).
* The depth-resolution limit of DIH, eq. 23 ``dz = d^2 / lambda``: :func:`dih_depth_resolution`.
* The depth-resolution limit of the plenoptic camera, eq. 22 (Deem et al. 2015, the paper's
  [29]): :func:`plenoptic_depth_resolution`, as printed and in a consistent paraxial form.
  The two differ by a factor of 5 at the paper's parameters; the paper quotes 0.24 mm, which
  is neither (0.468 mm printed, 0.097 mm paraxial; the printed form gives 0.237 mm with twice
  the pixels per lenslet): see the function's notes.

All hand-written NumPy (a few lines of linear algebra each); no loops over particles.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mitpiv.errors import ConfigError, check_positive

__all__ = ["PAPER_DOT_CARD", "StackDewarp", "fit_stack_dewarp", "dot_card_points", "dot_card_observations",
           "locate_dots_in_stack",
           "paper_alphas", "PAPER_ALPHA_RANGES", "model_error", "z_uncertainty", "velocity_sd_for_model_error",
           "z_uncertainty_quadrature", "power_law_fit",
           "dih_depth_resolution", "plenoptic_depth_resolution", "DEPTH_RESOLUTION_FORMS"]

#: The paper's dot card and traverse (ch. V.A): 1 mm dots at 3 mm pitch, 25 depths every
#: 2.5 mm from 30 mm in front of to 30 mm behind the focal plane.
PAPER_DOT_CARD = {"dot_diameter_mm": 1.0, "pitch_mm": 3.0, "depths_mm": tuple(np.arange(-30.0, 30.0 + 1e-9, 2.5))}

#: Focal-stack alpha limits of the paper (ch. V.A): drop impact +-30 mm, pellets +-200 mm.
PAPER_ALPHA_RANGES = {"drop_impact": (0.914, 1.139), "pellets": (0.923, 1.259)}


def _monomials(degree: int):
    return [(a, b, c) for t in range(degree + 1) for a in range(t + 1) for b in range(t + 1 - a) for c in [t - a - b]]


def _design(q, degree):
    return np.stack([q[..., 0] ** a * q[..., 1] ** b * q[..., 2] ** c for a, b, c in _monomials(degree)], axis=-1)


@dataclass
class StackDewarp:
    """Polynomial map from focal-stack locations ``(u, v, alpha)`` (refocus-plane position
    [mm or px] and refocus parameter) to object space ``(x, y, z)`` [mm]: every monomial
    ``u^a v^b alpha^c`` with ``a + b + c <= degree`` of the normalised coordinates
    ``(q - centre) / scale``; ``coef`` (n_terms, 3)."""

    coef: np.ndarray
    degree: int
    centre: np.ndarray
    scale: np.ndarray
    rms_mm: np.ndarray  # (3,) fit residual RMS per output coordinate

    @property
    def n_terms(self) -> int:
        return len(_monomials(self.degree))

    def __call__(self, uva) -> np.ndarray:
        """Object-space points (..., 3) [mm] of stack locations (..., 3)."""
        q = (np.asarray(uva, dtype=np.float64) - self.centre) / self.scale
        return _design(q, self.degree) @ self.coef


def fit_stack_dewarp(uva, xyz, *, degree: int = 2) -> StackDewarp:
    """Least-squares :class:`StackDewarp` (the paper's "3D second order polynomial",
    ``degree=2``) from stack locations ``uva`` (N, 3) of known points ``xyz`` (N, 3) [mm]."""
    uva = np.asarray(uva, dtype=np.float64).reshape(-1, 3)
    xyz = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    if uva.shape != xyz.shape:
        raise ConfigError(f"fit_stack_dewarp: {uva.shape[0]} stack locations but {xyz.shape[0]} object points; "
                          "give one object point per location.")
    if isinstance(degree, bool) or not isinstance(degree, int | np.integer) or not 1 <= degree <= 4:
        raise ConfigError(f"fit_stack_dewarp: 'degree' must be an integer in [1, 4] (the paper: 2), got {degree!r}.")
    if not (np.all(np.isfinite(uva)) and np.all(np.isfinite(xyz))):
        raise ConfigError("fit_stack_dewarp: the locations and points must be finite; drop the dots not found.")
    n_terms = len(_monomials(int(degree)))
    if uva.shape[0] < 2 * n_terms:
        raise ConfigError(f"fit_stack_dewarp: {uva.shape[0]} dots for {n_terms} terms per coordinate; image at least "
                          f"{2 * n_terms} dots (more depths or a larger card) or lower 'degree'.")
    if np.unique(np.round(uva[:, 2], 12)).size <= degree:
        raise ConfigError(f"fit_stack_dewarp: degree {degree} in alpha needs dots at >= {degree + 1} depths.")
    centre = uva.mean(axis=0)
    scale = np.maximum(uva.std(axis=0), 1e-12)
    a = _design((uva - centre) / scale, int(degree))
    coef, *_ = np.linalg.lstsq(a, xyz, rcond=None)
    rms = np.sqrt(np.mean((a @ coef - xyz) ** 2, axis=0))
    return StackDewarp(coef, int(degree), centre, scale, rms)


def dot_card_points(*, field_mm, pitch_mm: float = 3.0, depths_mm=PAPER_DOT_CARD["depths_mm"]) -> np.ndarray:
    """Dot centres (n_depths, n_dots, 3) [mm] of a card facing the camera: a centred
    rectangular grid of ``pitch_mm`` covering ``field_mm`` = (width, height) [mm], at each
    depth (offset from the focal plane, positive away from the camera) in ``depths_mm``.
    Coordinates are camera-local offsets from the focal-plane centre (x, y, depth)."""
    w, h = (float(v) for v in field_mm)
    if not (w > 0 and h > 0 and pitch_mm > 0):
        raise ConfigError(f"dot_card_points: field_mm and pitch_mm must be positive, got {field_mm!r}, {pitch_mm!r}.")
    nx, ny = int(math.floor(w / pitch_mm)) + 1, int(math.floor(h / pitch_mm)) + 1
    gx = (np.arange(nx) - 0.5 * (nx - 1)) * pitch_mm
    gy = (np.arange(ny) - 0.5 * (ny - 1)) * pitch_mm
    xx, yy = np.meshgrid(gx, gy)
    z = np.asarray(depths_mm, dtype=np.float64).reshape(-1)
    pts = np.broadcast_to(np.stack([xx.ravel(), yy.ravel()], -1), (z.size, xx.size, 2))
    return np.concatenate([pts, np.broadcast_to(z[:, None, None], (z.size, xx.size, 1))], axis=-1).copy()


def _aperture_samples(radius_mm: float, n_r: int = 6, n_phi: int = 12) -> np.ndarray:
    r = radius_mm * np.sqrt((np.arange(n_r) + 0.5) / n_r)
    phi = 2 * np.pi * (np.arange(n_phi) + 0.25) / n_phi
    return np.stack([np.outer(r, np.cos(phi)).ravel(), np.outer(r, np.sin(phi)).ravel()], -1)


def dot_card_observations(camera, points_mm, *, coords: str = "alpha") -> np.ndarray:
    """Focal-stack locations of object points through a plenoptic camera.

    Parameters
    ----------
    camera : PlenopticCamera
        Its main lens (with its ``distortion``) images the points.
    points_mm : (..., 3)
        Camera-local offsets from the focal-plane centre [mm]: (x, y, depth), depth positive
        away from the camera (e.g. :func:`dot_card_points`).
    coords : "alpha" | "nominal"
        "alpha": ``(u, v, alpha)``, the bundle centroid ``(u, v)`` [mm, on the refocus
        plane, sensor-frame axes] and ``alpha = s / s_i`` of the plane ``s`` behind the lens
        where the ray bundle (a symmetric grid of main-lens points) has the least RMS width.
        "nominal": the same location in object space by the ideal thin lens, the focal
        stack indexed in millimetres: depth ``z`` of ``alpha`` by eq. 11 and
        ``(x, y) = -(u, v) (s_o + z) / (alpha s_i)``; for the ideal lens this is the point
        itself, so a dewarp fitted on it only absorbs the lens's departures.

    Returns
    -------
    (..., 3) stack locations.
    """
    if coords not in ("alpha", "nominal"):
        raise ConfigError(f"dot_card_observations: 'coords' must be 'alpha' or 'nominal', got {coords!r}.")
    p = np.asarray(points_mm, dtype=np.float64)
    so, si, f = camera.focus_distance_mm, camera.image_distance_mm, camera.focal_length_mm
    loc = np.concatenate([p[..., :2], (so + p[..., 2:3])], axis=-1)
    a = _aperture_samples(camera.aperture_radius_mm)
    t = camera.image_side_tangents(loc[..., None, :], a)  # (..., K, 2)
    da = a - a.mean(axis=0)
    dt = t - t.mean(axis=-2, keepdims=True)
    s = -np.sum(da * dt, axis=(-1, -2)) / np.sum(dt * dt, axis=(-1, -2))  # least RMS width plane
    cen = a.mean(axis=0) + s[..., None] * t.mean(axis=-2)
    alpha = s / si
    if coords == "alpha":
        return np.concatenate([cen, alpha[..., None]], axis=-1)
    z_obj = f * s / (s - f)  # thin lens: the object distance imaged at s
    return np.concatenate([-cen * (z_obj / s)[..., None], (z_obj - so)[..., None]], axis=-1)


def locate_dots_in_stack(stack, z_mm, *, threshold: float | None = None, grow_px: int = 2,
                         min_area_px: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Bright dots of a dot card in its focal stack: in-plane centre and depth of each.

    The maximum-intensity map over the stack (read plane by plane) is segmented (above
    ``threshold`` over its median; default half-way to its maximum), each blob grown by
    ``grow_px``; blobs touching the border or under ``min_area_px`` are dropped. In every
    plane each blob's sharpness is the sum of the Tenengrad (squared Sobel gradient) over
    it; the depth is the plane of the largest sharpness, refined by a 3-point Gaussian; the
    centre the background-subtracted intensity centroid over the blob in that plane (the
    sharpest and its two neighbours, interpolated like the depth). Vectorised over dots.

    Parameters
    ----------
    stack : (n_z, H, W) array (may be memory-mapped)
    z_mm : (n_z,) monotonic depths of the planes

    Returns
    -------
    uv (N, 2) stack-pixel centres (column, row; pixel centres at integers), z (N,) [mm].
    """
    from scipy import ndimage

    from mitpiv.analysis.backlit import tenengrad
    from mitpiv.analysis.particles import gauss3_offset

    z = np.asarray(z_mm, dtype=np.float64).reshape(-1)
    if stack.ndim != 3 or stack.shape[0] != z.size or z.size < 3:
        raise ConfigError(f"locate_dots_in_stack: stack must be (n_z >= 3, H, W) with one depth per plane; got "
                          f"{stack.shape} and {z.size} depths.")
    mx = np.asarray(stack[0], dtype=np.float64).copy()
    for k in range(1, z.size):
        np.maximum(mx, np.asarray(stack[k], dtype=np.float64), out=mx)
    base = float(np.median(mx))
    thr = 0.5 * (float(mx.max()) - base) if threshold is None else float(threshold)
    lab, n = ndimage.label(mx - base > thr)
    if grow_px > 0 and n:
        grown = ndimage.grey_dilation(lab, size=(2 * grow_px + 1,) * 2)
        lab = np.where(lab > 0, lab, grown)
    if n == 0:
        return np.zeros((0, 2)), np.zeros(0)
    ids = np.arange(1, n + 1)
    edge = np.unique(np.concatenate([lab[0], lab[-1], lab[:, 0], lab[:, -1]]))
    area = ndimage.sum_labels(np.ones_like(mx), lab, ids)
    ids = ids[(area >= min_area_px) & ~np.isin(ids, edge)]
    if ids.size == 0:
        return np.zeros((0, 2)), np.zeros(0)
    rows, cols = np.indices(mx.shape, dtype=np.float64)
    sharp, w, wu, wv = (np.empty((z.size, ids.size)) for _ in range(4))
    for k in range(z.size):
        img = np.asarray(stack[k], dtype=np.float64)
        sharp[k] = ndimage.sum_labels(tenengrad(img), lab, ids)
        sig = np.clip(img - base, 0.0, None)
        w[k] = ndimage.sum_labels(sig, lab, ids)
        wu[k] = ndimage.sum_labels(sig * cols, lab, ids)
        wv[k] = ndimage.sum_labels(sig * rows, lab, ids)
    k = np.argmax(sharp, axis=0)
    r = np.arange(ids.size)
    kc = np.clip(k, 1, z.size - 2)
    off = np.where(k == kc, gauss3_offset(sharp[kc - 1, r], sharp[kc, r], sharp[kc + 1, r]), 0.0)
    zi = k + off
    # centre: interpolate the centroid linearly between the planes around the refined depth
    k0 = np.clip(np.floor(zi).astype(int), 0, z.size - 2)
    f = zi - k0
    cu0, cv0 = wu[k0, r] / np.maximum(w[k0, r], 1e-300), wv[k0, r] / np.maximum(w[k0, r], 1e-300)
    cu1, cv1 = wu[k0 + 1, r] / np.maximum(w[k0 + 1, r], 1e-300), wv[k0 + 1, r] / np.maximum(w[k0 + 1, r], 1e-300)
    uv = np.column_stack([cu0 + f * (cu1 - cu0), cv0 + f * (cv1 - cv0)])
    return uv, np.interp(zi, np.arange(z.size), z)


def paper_alphas(case: str = "drop_impact", n: int = 1000, *, alpha_range=None) -> np.ndarray:
    """The alphas of an ``n``-plane focal stack, evenly spaced in alpha between the paper's
    limits (:data:`PAPER_ALPHA_RANGES`, "focal stacks of 1000 images") or ``alpha_range``."""
    if alpha_range is None:
        if case not in PAPER_ALPHA_RANGES:
            raise ConfigError(f"paper_alphas: 'case' must be one of {sorted(PAPER_ALPHA_RANGES)}, got {case!r}.")
        alpha_range = PAPER_ALPHA_RANGES[case]
    lo, hi = (float(v) for v in alpha_range)
    if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 2:
        raise ConfigError(f"paper_alphas: 'n' must be an integer >= 2 planes, got {n!r}.")
    if not 0 < lo < hi:
        raise ConfigError(f"paper_alphas: alpha_range must be (lo, hi) with 0 < lo < hi, got {alpha_range!r}.")
    return np.linspace(lo, hi, int(n))


def model_error(positions_mm, displacements_mm, *, centre_mm=(0.0, 0.0, 0.0), axes=(0, 2)) -> dict:
    """The paper's model error (ch. VI.A.1, Fig. 25): for each component ``k`` in ``axes``,
    the displacement ``D_k`` is fitted linearly against the distance from the impact centre
    along that component, ``D_k ~ a_k + b_k (x_k - c_k)``; the model error is
    ``D_k - (a_k + b_k (x_k - c_k))`` at the measured position; its standard deviation is
    the statistic of Table 2.

    Parameters
    ----------
    positions_mm, displacements_mm : (N, 3)
        Frame-1 positions and frame-1 -> frame-2 displacements [mm].
    centre_mm : (3,)
        The impact centre.
    axes : components to evaluate (0 = x, 1 = y, 2 = z).

    Returns
    -------
    dict: per axis name ("x", "y", "z"): ``{"sd_mm", "slope", "intercept_mm", "errors_mm"}``.
    """
    p = np.asarray(positions_mm, dtype=np.float64).reshape(-1, 3)
    d = np.asarray(displacements_mm, dtype=np.float64).reshape(-1, 3)
    if p.shape != d.shape:
        raise ConfigError(f"model_error: {p.shape[0]} positions but {d.shape[0]} displacements.")
    if p.shape[0] < 3:
        raise ConfigError(f"model_error: a linear fit and its scatter need >= 3 particles, got {p.shape[0]}.")
    c = np.asarray(centre_mm, dtype=np.float64).reshape(3)
    out = {}
    for k in axes:
        r = p[:, k] - c[k]
        slope, intercept = np.polyfit(r, d[:, k], 1)
        e = d[:, k] - (intercept + slope * r)
        out["xyz"[k]] = {"sd_mm": float(np.std(e, ddof=1)), "slope": float(slope), "intercept_mm": float(intercept),
                         "errors_mm": e}
    return out


def velocity_sd_for_model_error(we: int, tau: float, sd_mm: float, *, dt_s: float, axis: str = "x",
                                n_sample: int = 20_000, seed: int = 0) -> float:
    """The film-plane velocity scatter [mm/s] of
    :func:`~mitpiv.physics.drop_impact.fragment_field` (Table 1 condition ``we``, time
    ``tau``) whose true field gives a model error (:func:`model_error`, displacements over
    ``dt_s``) of standard deviation ``sd_mm`` along ``axis``: solved by Brent's method
    (:func:`scipy.optimize.brentq`, to 0.1 mm/s) on one large field of ``n_sample``
    fragments, the same draws at every trial (common random numbers, so the root is that
    of a smooth function). With ``n_sample`` 20 000 the root's sampling error is ~0.5 %.

    Raises :class:`~mitpiv.errors.ConfigError` if ``sd_mm`` is below the crown model's own
    residual (no scatter: the spread of detachment times alone departs from a linear law).
    """
    from scipy.optimize import brentq

    from mitpiv.physics.drop_impact import condition, fragment_field

    sd_mm = check_positive("sd_mm", sd_mm, owner="velocity_sd_for_model_error", unit="mm")
    dt_s = check_positive("dt_s", dt_s, owner="velocity_sd_for_model_error", unit="s")
    if axis not in ("x", "z"):
        raise ConfigError(f"velocity_sd_for_model_error: axis must be 'x' or 'z' (the film plane), got {axis!r}.")
    row = condition(we)

    def sd_of(vsd):
        f = fragment_field(we, tau, d0_mm=row.d0_mm, v0_m_s=row.v0_m_s, n_fragments=int(n_sample),
                           velocity_sd_mm_s=float(vsd), seed=seed)
        return model_error(f["positions_mm"], f["velocities_mm_s"] * dt_s)[axis]["sd_mm"]

    floor = sd_of(0.0)
    if sd_mm <= floor:
        raise ConfigError(f"velocity_sd_for_model_error: sd_mm = {sd_mm!r} mm is at or below the {axis} model error of the "
                          f"crown model without scatter ({floor:.4g} mm at We {we}, tau {tau}); ask for more than that.")
    hi = 4.0 * sd_mm / dt_s
    for _ in range(20):  # the fit absorbs a fraction < 1 of the scatter: widen until bracketed
        if sd_of(hi) >= sd_mm:
            break
        hi *= 2.0
    else:
        raise ConfigError(f"velocity_sd_for_model_error: no scatter up to {hi:.3g} mm/s gives a {axis} model error of "
                          f"{sd_mm!r} mm at We {we}, tau {tau}; check sd_mm and dt_s.")
    return float(brentq(lambda v: sd_of(v) - sd_mm, 0.0, hi, xtol=0.1))


def z_uncertainty(sd_x_mm, sd_z_mm):
    """The z positional uncertainty of Table 2: the z model-error standard deviation less
    the x one ("assuming negligible uncertainty in the x direction"): ``sd_z - sd_x``
    (Table 2's every row, e.g. 0.411 - 0.263 = 0.148 mm at We 784, 320 ms)."""
    return np.asarray(sd_z_mm, dtype=np.float64) - np.asarray(sd_x_mm, dtype=np.float64)


def z_uncertainty_quadrature(sd_x_mm, sd_z_mm):
    """The z uncertainty if the flow's scatter and the depth error are independent and add
    in quadrature: ``sqrt(sd_z^2 - sd_x^2)`` (0 where ``sd_z <= sd_x``). The paper's
    :func:`z_uncertainty` subtracts the standard deviations linearly, which understates an
    independent error (0.316 against 0.148 mm for Table 2's 0.263 and 0.411 mm)."""
    x = np.asarray(sd_x_mm, dtype=np.float64)
    z = np.asarray(sd_z_mm, dtype=np.float64)
    return np.sqrt(np.maximum(z**2 - x**2, 0.0))


def power_law_fit(tau, ratio) -> tuple[float, float]:
    """``(q, n)`` of ``ratio = q tau^n`` (e.g. ``d/d0`` or ``v_r/v0`` against ``tau``, Figs.
    28-29), least squares on ``log ratio = log q + n log tau``."""
    t = np.asarray(tau, dtype=np.float64).ravel()
    r = np.asarray(ratio, dtype=np.float64).ravel()
    if t.shape != r.shape or t.size < 2 or np.unique(t).size < 2:
        raise ConfigError(f"power_law_fit: need matching tau and ratio at >= 2 distinct tau, got {t.size} and {r.size}.")
    if np.any(t <= 0) or np.any(r <= 0) or not (np.all(np.isfinite(t)) and np.all(np.isfinite(r))):
        raise ConfigError("power_law_fit: tau and ratio must be finite and > 0 (a power law is fitted on logarithms).")
    n, logq = np.polyfit(np.log(t), np.log(r), 1)
    return float(np.exp(logq)), float(n)


def dih_depth_resolution(d_mm, wavelength_nm):
    """Eq. 23, the theoretical depth resolution of DIH: ``dz = d^2 / lambda`` [mm]."""
    lam = float(wavelength_nm) * 1e-6
    if not lam > 0:
        raise ConfigError(f"dih_depth_resolution: wavelength_nm must be > 0, got {wavelength_nm!r}.")
    return np.asarray(d_mm, dtype=np.float64) ** 2 / lam


#: The forms of :func:`plenoptic_depth_resolution`.
DEPTH_RESOLUTION_FORMS = ("printed", "paraxial")


def plenoptic_depth_resolution(*, aperture_mm, pixels_per_lenslet, lenslet_mm, focal_length_mm, image_distance_mm,
                               form: str = "printed") -> float:
    """Eq. 22, the worst-case (nominal focal plane) depth resolution of a plenoptic 1.0
    camera [mm] (Deem et al. 2015, the paper's [29]).

    Each term of eq. 22 is the object distance ``z(h)`` of the on-axis point whose ray
    through the main lens at height ``h`` lands on the edge of the central lenslet, ``d_mu /
    2`` off the axis on the far side: ``h = d_M (1 - 2/N_p) / 2`` (the aperture less the two
    edge pixels of the lenslet's angular sampling) and ``h = d_M / 2`` (the full aperture);
    ``dz = z(h_1) - z(h_2)``.

    form "printed"
        The paper's expression, ``z(h) = h / tan(h/f_M - atan((2h + d_mu) / (2 s_i)))``. Its
        second term is garbled in print (an angle ``d_M`` less an angle, over ``2 s_i``) and
        is read as the first term with ``N_p -> infinity``, the only reading that keeps its
        dimensions. It mixes the paraxial lens deflection ``h/f_M`` with exact ray angles
        (atan), so even with ``d_mu = 0`` the two terms differ (0.37 mm at the paper's
        parameters), where a point in focus images to a point and the resolution must
        vanish.
    form "paraxial"
        The same construction in the paraxial thin lens throughout:
        ``1/z(h) = 1/f_M - 1/s_i - d_mu / (2 h s_i)``; 0 for ``d_mu = 0``.

    At the paper's parameters (f/2.8 105 mm lens, N_p = 14, 77 um lenslets, s_i = 191.5 mm)
    the printed form gives 0.468 mm and the paraxial one 0.097 mm; the paper quotes "about
    0.24 mm" without the numbers it used. The printed form gives 0.237 mm at N_p = 28, twice
    the pixels across a lenslet: a possible reading, not a stated one. In both forms dz grows
    with the lenslet diameter (paraxially in proportion to it), where the paper's text says
    the resolution improves as the microlens diameter increases; it does improve with N_p.
    """
    vals = {"aperture_mm": aperture_mm, "lenslet_mm": lenslet_mm, "focal_length_mm": focal_length_mm,
            "image_distance_mm": image_distance_mm}
    for name, v in vals.items():
        if not (np.isfinite(v) and v > 0):
            raise ConfigError(f"plenoptic_depth_resolution: {name} must be finite and > 0, got {v!r}.")
    if not (np.isfinite(pixels_per_lenslet) and pixels_per_lenslet > 2):
        raise ConfigError(f"plenoptic_depth_resolution: pixels_per_lenslet must be > 2 (the two edge pixels are "
                          f"left out), got {pixels_per_lenslet!r}.")
    if image_distance_mm <= focal_length_mm:
        raise ConfigError(f"plenoptic_depth_resolution: image_distance_mm ({image_distance_mm}) must exceed "
                          f"focal_length_mm ({focal_length_mm}) for a real image.")
    if form not in DEPTH_RESOLUTION_FORMS:
        raise ConfigError(f"plenoptic_depth_resolution: form must be one of {DEPTH_RESOLUTION_FORMS}, got {form!r}.")
    f, si, dmu = float(focal_length_mm), float(image_distance_mm), float(lenslet_mm)
    h1, h2 = 0.5 * aperture_mm * (1.0 - 2.0 / pixels_per_lenslet), 0.5 * aperture_mm

    def z(h):
        if form == "printed":
            return h / math.tan(h / f - math.atan((2.0 * h + dmu) / (2.0 * si)))
        return 1.0 / (1.0 / f - 1.0 / si - dmu / (2.0 * h * si))

    return float(z(h1) - z(h2))
