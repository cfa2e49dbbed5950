"""Digital in-line holography (DIH) as a comparison modality: wave optics in NumPy/SciPy FFTs.

Geometry: a collimated coherent plane wave (``wavelength_nm``) travels along +z through a
field of particles at world positions (x, y, z) [mm] to a sensor in the plane
z = ``sensor_z_mm``, normal to z, centred on ``centre_xy_mm``; array row r and column c
of a hologram sit at y = y0 + (r + 0.5 - H/2) p, x = x0 + (c + 0.5 - W/2) p (row = +y).
A particle is an opaque disk (its silhouette) or, with ``phase_index``, a weak phase
object of the sphere's chord thickness; particle planes are handled by sequential
propagation from the source side to the sensor.

Propagation is the band-limited angular-spectrum method (Matsushima & Shimobaba 2009):
exact scalar diffraction, H = exp(i 2 pi z sqrt(1/lambda^2 - f^2)), evanescent waves
(f > 1/lambda) dropped, frequencies above f_lim = 1 / (lambda sqrt((2 z / S)^2 + 1)) cut
per axis, S the FFT length, so the transfer function is never undersampled. ``pad`` (2x
zero padding) gives linear rather than circular convolution for fields that are zero
outside; :func:`record` instead simulates the plane wave on a guard band around the sensor.

Reconstruction back-propagates the background-normalised hologram (zero phase) to each
depth: :func:`focal_stack` returns the amplitude, with the plane's FFT done once and one
inverse FFT per plane. :func:`detect` applies the hybrid detection of backlit imaging
(:func:`mitpiv.analysis.backlit.hybrid_detect`) to the intensity stack.
"""

from __future__ import annotations

import logging
import math
import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from mitpiv.errors import ConfigError, MitpivWarning, check_positive
from mitpiv.progress import Progress, track

__all__ = ["Hologram", "record", "propagate", "focal_stack", "iter_planes", "transfer_function", "detect",
           "depth_of_focus_mm", "critical_distance_mm"]

log = logging.getLogger(__name__)


def _wl_mm(wavelength_nm):
    return check_positive("wavelength_nm", wavelength_nm, owner="holography", unit="nm") * 1e-6


def critical_distance_mm(n: int, pixel_um: float, wavelength_nm: float) -> float:
    """z_c = N dx^2 / lambda: beyond it the band limit removes frequencies the grid holds,
    so the reconstructed lateral resolution falls (the field is too small for the distance)."""
    dx = pixel_um * 1e-3
    return n * dx * dx / _wl_mm(wavelength_nm)


def depth_of_focus_mm(diameter_mm, wavelength_nm: float):
    """The d^2 / lambda depth-of-focus estimate of a particle of diameter d."""
    return np.asarray(diameter_mm, dtype=np.float64) ** 2 / _wl_mm(wavelength_nm)


def transfer_function(shape, dx_mm: float, dz_mm: float, wavelength_mm: float, *, band_limit: bool = True) -> np.ndarray:
    """Band-limited angular-spectrum transfer function on the FFT grid of ``shape`` (rows, cols)."""
    ny, nx = shape
    fy = np.fft.fftfreq(ny, d=dx_mm)[:, None]
    fx = np.fft.fftfreq(nx, d=dx_mm)[None, :]
    arg = 1.0 / wavelength_mm**2 - fx**2 - fy**2
    prop = arg > 0
    H = np.where(prop, np.exp(2j * np.pi * dz_mm * np.sqrt(np.where(prop, arg, 0.0))), 0.0)
    if band_limit and dz_mm != 0.0:
        H = H * _band(fx, fy, shape, dx_mm, dz_mm, wavelength_mm)
    return H


def _band(fx, fy, shape, dx_mm, dz_mm, wavelength_mm):
    """Matsushima-Shimobaba band limit per axis, f_lim = 1 / (lambda sqrt((2 z / S)^2 + 1))."""
    ny, nx = shape
    lim_x = 1.0 / (wavelength_mm * math.sqrt((2.0 * dz_mm / (nx * dx_mm)) ** 2 + 1.0))
    lim_y = 1.0 / (wavelength_mm * math.sqrt((2.0 * dz_mm / (ny * dx_mm)) ** 2 + 1.0))
    return (np.abs(fx) < lim_x) & (np.abs(fy) < lim_y)


def propagate(field, dz_mm: float, *, pixel_um: float, wavelength_nm: float, pad: bool = True,
              band_limit: bool = True) -> np.ndarray:
    """Propagate a complex field sampled at ``pixel_um`` by ``dz_mm`` (either sign) with the
    band-limited angular-spectrum method. ``pad``: zero-pad to twice the size (linear
    convolution, for a field that is zero outside); False: periodic field."""
    u = np.asarray(field)
    if u.ndim != 2 or u.size == 0:
        raise ConfigError(f"propagate: field must be a non-empty 2D array, got shape {u.shape}.")
    if not np.all(np.isfinite(u)):
        raise ConfigError("propagate: the field holds NaN or infinite values.")
    dz = float(dz_mm)
    if not math.isfinite(dz):
        raise ConfigError(f"propagate: dz_mm must be finite, got {dz_mm!r}.")
    dx = check_positive("pixel_um", pixel_um, owner="propagate", unit="um") * 1e-3
    wl = _wl_mm(wavelength_nm)
    from scipy import fft

    ny, nx = u.shape
    shape = (2 * ny, 2 * nx) if pad else (ny, nx)
    U = fft.fft2(u.astype(np.complex128), s=shape, workers=-1)
    out = fft.ifft2(U * transfer_function(shape, dx, dz, wl, band_limit=band_limit), workers=-1)
    return out[:ny, :nx]


@dataclass
class Hologram:
    """A recorded hologram and its geometry. ``image``: intensity per pixel (1 = the
    undisturbed beam) or sensor counts when a sensor model was applied."""

    image: np.ndarray
    pixel_um: float
    wavelength_nm: float
    sensor_z_mm: float
    centre_xy_mm: tuple = (0.0, 0.0)
    background: float = 1.0
    info: dict = field(default_factory=dict)

    @property
    def shape(self) -> tuple:
        return self.image.shape

    def pixel_to_world(self, col, row) -> tuple[np.ndarray, np.ndarray]:
        """Continuous array indices (pixel centres at integers) -> world x, y [mm]."""
        p = self.pixel_um * 1e-3
        h, w = self.image.shape
        return (self.centre_xy_mm[0] + (np.asarray(col) + 0.5 - w / 2) * p,
                self.centre_xy_mm[1] + (np.asarray(row) + 0.5 - h / 2) * p)


def _particles(particles, diameters_mm):
    if isinstance(particles, dict):
        pos, d = particles["positions_mm"], particles["diameters_mm"]
    else:
        pos, d = particles, diameters_mm
    if d is None:
        raise ConfigError("record: give diameters_mm (or a dict with positions_mm and diameters_mm).")
    pos = np.asarray(pos, dtype=np.float64).reshape(-1, 3)
    d = np.broadcast_to(np.asarray(d, dtype=np.float64), (pos.shape[0],)).copy()
    if not (np.all(np.isfinite(pos)) and np.all(np.isfinite(d))) or np.any(d <= 0):
        raise ConfigError("record: particle positions must be finite and diameters_mm > 0.")
    return pos, d


def _disk_transmittance(shape, x0, y0, dx, centres, radii, phase_index, wl, batch_elems=8_000_000):
    """Transmittance of the disks of one plane on the grid x0 + j dx, y0 + i dx: an
    area-weighted edge (linear ramp over one sample, exact coverage to O(dx/r)); opaque, or
    exp(i k (n - 1) chord) for phase objects. Vectorised over the disks: each one's
    (2h + 1)^2 box of samples around it (h from the largest radius), overlaps multiplied."""
    ny, nx = shape
    t = np.ones(shape, np.complex128)
    n = len(radii)
    if n == 0:
        return t
    h = int(np.ceil(float(np.max(radii)) / dx)) + 2
    o = np.arange(-h, h + 1)
    per = max(1, batch_elems // o.size**2)
    flat_t = t.reshape(-1)
    for b in range(0, n, per):
        c, r = centres[b:b + per], np.asarray(radii[b:b + per])[:, None, None]
        ci = np.rint((c[:, 0] - x0) / dx).astype(np.int64)
        ri = np.rint((c[:, 1] - y0) / dx).astype(np.int64)
        cols = ci[:, None, None] + o[None, None, :]
        rows = ri[:, None, None] + o[None, :, None]
        rho = np.hypot(x0 + cols * dx - c[:, 0, None, None], y0 + rows * dx - c[:, 1, None, None])
        if phase_index is None:
            factor = 1.0 - np.clip(0.5 + (r - rho) / dx, 0.0, 1.0)
        else:
            chord = 2.0 * np.sqrt(np.clip(r * r - rho * rho, 0.0, None))
            factor = np.exp(2j * np.pi / wl * (phase_index - 1.0) * chord)
        use = (rows >= 0) & (rows < ny) & (cols >= 0) & (cols < nx) & (factor != 1.0)
        np.multiply.at(flat_t, (rows * nx + cols)[use], factor[use])
    return t


def record(particles, diameters_mm=None, *, sensor_z_mm: float, wavelength_nm: float = 532.0, pixel_um: float = 5.5,
           resolution=(1024, 1024), centre_xy_mm=(0.0, 0.0), oversample: int = 2, guard_mm: float | None = None,
           phase_index: float | None = None, plane_tolerance_mm: float = 0.0, sensor=None, seed: int = 0,
           phase_screens=None, progress: Progress = None) -> Hologram:
    """Record the in-line hologram of a particle field.

    particles : (N, 3) positions [mm] (with ``diameters_mm``) or a dict with
        ``positions_mm`` and ``diameters_mm`` (as :mod:`mitpiv.physics.droplets` returns).
        Particles must lie before the sensor (z < sensor_z_mm).
    resolution : (W, H) sensor pixels of ``pixel_um``; the field is simulated ``oversample``
        times finer and the intensity integrated over each pixel.
    guard_mm : band simulated around the sensor so that diffraction from particles near
        the edge is not wrapped; default 2 z_max lambda / d_min (a few diffraction lobes of
        the smallest particle), at most one sensor width.
    phase_index : None: opaque particles; else the relative refractive index of weak
        phase objects (transmittance exp(i k (n - 1) chord)).
    plane_tolerance_mm : particles whose z differ by less share one propagation plane
        (0: one plane per distinct z, exact for thin disks).
    sensor : optional :class:`mitpiv.imaging.SensorModel` (bit depth, noise) applied to
        the pixel intensities.
    phase_screens : optional sequence of ``(z_mm, phase)`` with ``phase(x_mm, y_mm)`` the
        phase [rad] a thin refractive-index disturbance adds at plane ``z_mm`` (e.g. the
        projected optical path of shock waves, :func:`mitpiv.physics.shocks.shock_phase`),
        called on the simulation grid ((ny, nx) arrays of sample centres); applied as
        ``exp(i phase)`` in z order with the particle planes (before the sensor).
    """
    pos, d = _particles(particles, diameters_mm)
    screens = sorted(((float(zs_), fn) for zs_, fn in (phase_screens or ())), key=lambda e: e[0])
    if screens and (not all(callable(fn) for _, fn in screens) or screens[-1][0] >= float(sensor_z_mm)):
        raise ConfigError("record: phase_screens must be (z_mm, callable) pairs with z_mm < sensor_z_mm.")
    if np.ndim(resolution) != 1 or len(resolution) != 2:
        raise ConfigError(f"record: resolution must be (width, height) in pixels, got {resolution!r}.")
    W, H = (int(v) for v in resolution)
    if guard_mm is not None and not (np.isfinite(guard_mm) and guard_mm >= 0):
        raise ConfigError(f"record: guard_mm must be >= 0 mm (or None for the default), got {guard_mm!r}.")
    if not (np.isfinite(plane_tolerance_mm) and plane_tolerance_mm >= 0):
        raise ConfigError(f"record: plane_tolerance_mm must be >= 0 mm, got {plane_tolerance_mm!r}.")
    if W < 8 or H < 8:
        raise ConfigError(f"record: resolution must be at least 8x8 pixels, got {resolution!r}.")
    if int(oversample) != oversample or oversample < 1:
        raise ConfigError(f"record: oversample must be an integer >= 1, got {oversample!r}.")
    wl = _wl_mm(wavelength_nm)
    p = check_positive("pixel_um", pixel_um, owner="record", unit="um") * 1e-3
    dx = p / oversample
    zs = float(sensor_z_mm)
    if pos.shape[0] and np.any(pos[:, 2] >= zs):
        k = int(np.argmax(pos[:, 2]))
        raise ConfigError(f"record: particle {k} at z = {pos[k, 2]:.4g} mm is not before the sensor (sensor_z_mm = {zs}); "
                          f"particles must have z < sensor_z_mm.")
    if pos.shape[0] and d.min() < 2.0 * dx:
        raise ConfigError(f"record: the smallest particle ({d.min() * 1e3:.3g} um) spans less than 2 simulation samples "
                          f"of {dx * 1e3:.3g} um; raise oversample to at least {math.ceil(2 * p / d.min())}.")
    zmax = float(zs - pos[:, 2].min()) if pos.shape[0] else 0.0
    if guard_mm is None:
        guard_mm = min(2.0 * zmax * wl / d.min(), max(W, H) * p) if pos.shape[0] else 0.0
    if pos.shape[0] and d.min() < 2.0 * p:
        warnings.warn(f"record: the smallest particle ({d.min() * 1e3:.3g} um) is under 2 sensor pixels of {p * 1e3:.3g} um: "
                      f"its diffraction fringes (spatial frequency ~1/d) alias on the sensor. Use smaller pixels or larger "
                      f"particles.", MitpivWarning, stacklevel=2)
    lobe = 1.22 * wl * zmax / d.min() if pos.shape[0] else 0.0
    if float(guard_mm) < lobe:
        warnings.warn(f"record: guard_mm = {float(guard_mm):.3g} mm is smaller than the first dark ring of the smallest "
                      f"particle's pattern ({lobe:.3g} mm at {zmax:.3g} mm): diffraction of particles near the field edge "
                      f"wraps around the periodic simulation. Enlarge guard_mm (the grid, and the cost, grow with it).",
                      MitpivWarning, stacklevel=2)
    g = int(math.ceil(float(guard_mm) / dx))
    nx, ny = W * oversample + 2 * g, H * oversample + 2 * g
    zc = min(nx, ny) * dx * dx / wl
    x0 = centre_xy_mm[0] + (0.5 - nx / 2) * dx  # sample centres x0 + j dx, y0 + i dx
    y0 = centre_xy_mm[1] + (0.5 - ny / 2) * dx
    u = np.ones((ny, nx), np.complex128)
    order = np.argsort(pos[:, 2], kind="stable")
    pos, d = pos[order], d[order]
    # planes: consecutive particles within plane_tolerance_mm share the plane of their mean z
    brk = np.nonzero(np.diff(pos[:, 2]) > plane_tolerance_mm)[0] + 1 if pos.shape[0] else np.zeros(0, int)
    groups = np.split(np.arange(pos.shape[0]), brk) if pos.shape[0] else []
    t0 = time.perf_counter()
    z_here = None
    events = sorted([(float(pos[idx, 2].mean()), 0, k) for k, idx in enumerate(groups)]
                    + [(zq, 1, k) for k, (zq, _) in enumerate(screens)])
    if screens:
        gx = x0 + np.arange(nx) * dx
        gy = y0 + np.arange(ny) * dx
    for zp, kind, k in track(events, desc="hologram: planes", progress=progress, unit="plane"):
        if z_here is not None and zp != z_here:
            u = propagate(u, zp - z_here, pixel_um=dx * 1e3, wavelength_nm=wavelength_nm, pad=False)
        if kind == 0:
            idx = groups[k]
            u *= _disk_transmittance((ny, nx), x0, y0, dx, pos[idx, :2], d[idx] / 2, phase_index, wl)
        else:
            u *= np.exp(1j * np.asarray(screens[k][1](gx[None, :], gy[:, None]), dtype=np.float64))
        z_here = zp
    if z_here is not None:
        u = propagate(u, zs - z_here, pixel_um=dx * 1e3, wavelength_nm=wavelength_nm, pad=False)
    inten = np.abs(u[g:g + H * oversample, g:g + W * oversample]) ** 2
    img = inten.reshape(H, oversample, W, oversample).mean(axis=(1, 3))
    info = {"planes": len(groups), "phase_screens": len(screens), "grid": [nx, ny], "guard_mm": g * dx, "oversample": int(oversample),
            "critical_distance_mm": zc, "seconds": time.perf_counter() - t0, "n_particles": int(pos.shape[0])}
    log.debug("record: %d particles in %d planes on a %dx%d grid, %.1f s", info["n_particles"], len(groups), nx, ny,
              info["seconds"])
    background = 1.0
    if sensor is not None:
        from mitpiv.imaging import SensorModel, apply_sensor

        model = sensor if isinstance(sensor, SensorModel) else SensorModel(**sensor)
        counts = apply_sensor(img, model, seed=seed)
        # counts of the undisturbed beam: the same (linear) model without noise or quantisation
        quiet = SensorModel(**{**model.to_dict(), "shot_noise": False, "read_noise_e": 0.0, "gaussian_noise_percent": 0.0,
                               "dark_current_e_per_s": 0.0, "bit_depth": None, "full_well_e": None})
        clean = np.asarray(apply_sensor(img, quiet), dtype=np.float64) - model.black_level
        background = float(clean.max() / img.max()) + model.black_level if img.max() > 0 else 1.0
        img = counts
        info["sensor"] = model.to_dict()
    return Hologram(img, float(pixel_um), float(wavelength_nm), zs, tuple(float(c) for c in centre_xy_mm), background,
                    info)


def _hologram_args(hologram, pixel_um, wavelength_nm, background):
    if isinstance(hologram, Hologram):
        img = np.asarray(hologram.image, dtype=np.float64)
        return img, hologram.pixel_um, hologram.wavelength_nm, hologram.background if background is None else background
    img = np.asarray(hologram, dtype=np.float64)
    if pixel_um is None or wavelength_nm is None:
        raise ConfigError("focal_stack: a bare array needs pixel_um and wavelength_nm (or pass a Hologram).")
    return img, pixel_um, wavelength_nm, (float(np.median(img)) if background is None else background)


def iter_planes(hologram, z_mm, *, pixel_um=None, wavelength_nm=None, background=None, pad: bool = False,
                band_limit: bool = True):
    """Yield (k, complex64 reconstructed field, up to a constant phase) for each distance in ``z_mm`` (from the
    sensor back towards the source, mm > 0): the normalised hologram's spectrum is computed
    once, each plane costs one multiplication and one inverse FFT."""
    from scipy import fft

    img, pix, wln, bg = _hologram_args(hologram, pixel_um, wavelength_nm, background)
    if img.ndim != 2 or not np.all(np.isfinite(img)):
        raise ConfigError(f"focal_stack: the hologram must be a finite 2D array, got shape {img.shape}.")
    if not bg > 0:
        raise ConfigError(f"focal_stack: background must be > 0 (the undisturbed beam level), got {bg!r}.")
    z = np.atleast_1d(np.asarray(z_mm, dtype=np.float64))
    if z.ndim != 1 or z.size == 0 or not np.all(np.isfinite(z)):
        raise ConfigError("focal_stack: z_mm must be a non-empty 1D sequence of finite distances [mm].")
    dx = check_positive("pixel_um", pix, owner="focal_stack", unit="um") * 1e-3
    wl = _wl_mm(wln)
    ny, nx = img.shape
    shape = (2 * ny, 2 * nx) if pad else (ny, nx)
    spec = fft.fft2((img / bg).astype(np.complex64), s=shape, workers=-1)
    fy = np.fft.fftfreq(shape[0], d=dx).astype(np.float32)[:, None]
    fx = np.fft.fftfreq(shape[1], d=dx).astype(np.float32)[None, :]
    arg = (1.0 / wl**2 - fx.astype(np.float64) ** 2 - fy.astype(np.float64) ** 2)
    prop = arg > 0
    # kz - k0 in float64, then single precision: the constant phase k0 z (1e5 rad) would
    # cost float32 its precision and does not change the reconstructed amplitude
    dkz = (2.0 * np.pi * (np.sqrt(np.where(prop, arg, 0.0)) - 1.0 / wl)).astype(np.float32)
    for k, zk in enumerate(z):
        # back-propagation by -z (up to the constant phase exp(-i k0 z)); evanescent and
        # band-limited parts cut
        ph = np.where(prop, np.exp(-1j * (dkz * np.float32(zk))), 0).astype(np.complex64)
        if band_limit:
            ph *= _band(fx, fy, shape, dx, zk, wl)
        yield k, fft.ifft2(spec * ph, workers=-1)[:ny, :nx]


def focal_stack(hologram, z_mm, *, pixel_um=None, wavelength_nm=None, background=None, pad: bool = False,
                out=None, progress: Progress = None) -> np.ndarray:
    """Amplitude of the hologram reconstructed at each distance ``z_mm`` from the sensor:
    (n_z, H, W) float32 (1 = background). ``out``: stream into this ``.npy`` file (memory
    map) for stacks larger than memory."""
    from mitpiv.io.arrays import stack_output

    img = hologram.image if isinstance(hologram, Hologram) else np.asarray(hologram)
    z = np.atleast_1d(np.asarray(z_mm, dtype=np.float64))
    t0 = time.perf_counter()
    with stack_output((z.size,) + tuple(img.shape), out, "focal_stack") as stack:
        planes = iter_planes(hologram, z, pixel_um=pixel_um, wavelength_nm=wavelength_nm, background=background, pad=pad)
        for k, plane in track(planes, total=z.size, desc="hologram focal stack: planes", progress=progress, unit="plane"):
            stack[k] = np.abs(plane)
        log.debug("hologram focal stack: %d planes, %.1f ms/plane", z.size, (time.perf_counter() - t0) / z.size * 1e3)
        result = stack if out is None else None
    return result if out is None else np.load(out, mmap_mode="r")


def detect(hologram: Hologram, z_mm, *, threshold: float = 0.5, min_peak_darkness: float = 0.8, min_area_px: int = 3,
           pad: bool = False, **kwargs):
    """Hybrid detection (minimum intensity + Tenengrad, :func:`~mitpiv.analysis.backlit.hybrid_detect`)
    on the intensity focal stack; world positions (z = sensor_z - distance) and diameters
    [mm] filled in. Regions must reach ``min_peak_darkness`` (an opaque particle in focus
    is nearly black; the dark fringes of defocused diffraction rings are not). Returns :class:`~mitpiv.analysis.backlit.BacklitDetections`."""
    from mitpiv.analysis.backlit import hybrid_detect

    if not isinstance(hologram, Hologram):
        raise ConfigError("detect: pass a Hologram (its geometry places the particles).")
    z = np.atleast_1d(np.asarray(z_mm, dtype=np.float64))
    stack = focal_stack(hologram, z, pad=pad) ** 2
    det = hybrid_detect(stack, z, background=1.0, threshold=threshold, min_area_px=min_area_px,
                        min_peak_darkness=min_peak_darkness, **kwargs)
    x, y = hologram.pixel_to_world(det.uv_px[:, 0], det.uv_px[:, 1])
    det.positions_mm = np.column_stack([x, y, hologram.sensor_z_mm - det.z_stack_mm])
    det.diameters_mm = det.diameter_px * hologram.pixel_um * 1e-3
    return det
