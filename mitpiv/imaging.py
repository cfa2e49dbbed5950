"""Post-optics on rendered images: PSF convolution and the camera sensor model.

The sensor chain (each stage optional, applied in this order, vectorised, seeded)::

    image [render units] --exposure--> mean photons per pixel
      --quantum_efficiency, shot_noise--> photoelectrons   (Poisson(QE * photons); QE thins a
                                                             Poisson stream into a Poisson stream)
      --dark_current--> + Poisson(dark_current_e_per_s * exposure_time_s)
      --full_well-->    min(electrons, full_well_e)
      --read_noise-->   + Normal(0, read_noise_e)
      --gain-->         counts = electrons / gain_e_per_count + black_level
      --gaussian_noise_percent--> + Normal(0, X/100 * peak counts)   (the simple model of
                                                             tomographic simulation studies)
      --bit_depth-->    round to integers, clip to [0, 2^bits - 1]

Exposure is a physical, scene-wide quantity, the same for every camera and frame; each
camera's counts follow the light its own aperture collects (``photometry``, below). So a
camera in forward scatter that receives three times the light of one in back scatter
records three times the counts, and of two cameras at f/4 and f/8 the first records four
times the counts of the second.

Photometry (``photometry``; :mod:`mitpiv.photometry`):

- ``"aperture"``: the exposed quantity is the power a pixel collects, the rendered value
  times the pixel's étendue (``V G`` [W], :func:`mitpiv.photometry.pixel_etendue`: the
  lens pupil's solid angle for radiance cameras, the pixel area for plenoptic ones, which
  render irradiance). ``exposure`` is then in photons per watt, and
  ``illumination_time_s`` gives it in physical units: ``t lambda / (h c)`` for the
  sheet's wavelength, with the scene rendered at the sheet's real irradiance.
- ``"image"``: the exposed quantity is the rendered value itself (photons per unit of
  pixel value), as for a set of pinhole cameras without apertures; every camera of the
  set must then record the same quantity (all radiance, or all irradiance).
- ``"auto"`` (default): ``"aperture"`` when every camera of the set states an aperture
  (a thin lens, a pinhole's ``psf_f_number`` or ``photometric_f_number``, a plenoptic main
  lens), ``"image"`` when none does or when the cameras are not known (plain arrays);
  a set that mixes both is refused with the fix.

``exposure`` is the primary model: photons per pixel per unit of the exposed quantity.
``peak_photons`` is the alternative that fixes the exposure from the data: the brightest
pixel *of the whole set of images* (every camera and frame of an experiment, see
:func:`apply_sensor_set`) becomes that many photons, i.e. ``exposure = peak_photons /
scene_peak``. ``illumination_time_s`` is the third, from physics. With none of them, the
exposed values are taken as photons (``exposure = 1``). Likewise the reference ``peak`` of ``gaussian_noise_percent`` is, unless
given, the noise-free peak count of the whole set, so the noise has one absolute sigma on
every image. :func:`apply_sensor` on one image treats that image as the whole set (or takes
the set's peak as ``scene_peak``).

With ``bit_depth`` the result is an unsigned integer array (uint8 for 8 bits, uint16 up to
16); without, float64 counts.
"""

from __future__ import annotations

import logging
import math
import numbers
import warnings
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, replace
from functools import lru_cache

import numpy as np

from mitpiv.errors import ConfigError, MitpivWarning, check_positive

__all__ = ["SensorModel", "SensorSetResult", "noise_free", "apply_sensor", "apply_sensor_set", "resolve_exposure", "resolve_photometry",
           "degenerate_counts",
           "convolve_psf", "decimated_convolve", "sensor_mean_variance", "PointPSFTable", "splat_points", "point_images"]

_log = logging.getLogger(__name__)
_BIT_DEPTHS = (8, 10, 12, 14, 16)
#: The sensor model's photometry modes (see the module docstring).
PHOTOMETRY = ("auto", "aperture", "image")


@dataclass(frozen=True)
class SensorModel:
    """Camera sensor parameters; ``None`` / ``False`` switches a stage off.

    Attributes
    ----------
    exposure : float or None
        Photons per pixel per unit of the exposed quantity (scene-wide): of the rendered
        value with ``photometry = "image"``, per watt collected with "aperture".
    peak_photons : float or None
        Alternative to ``exposure``: the maximum of the exposed quantity over the whole set
        of images (all cameras and frames; one image: its own maximum) becomes this many
        photons.
    illumination_time_s : float or None
        Alternative to ``exposure``: photons from physics, an exposure of
        ``t lambda / (h c)`` photons per watt, ``t`` the time the sheet lights the particles
        within the exposure [s] (a pulsed laser's pulse duration); needs "aperture"
        photometry and the scene rendered at the sheet's real irradiance.
    photometry : str
        "auto", "aperture" or "image" (see the module docstring).
    quantum_efficiency : float
        Electrons per photon, in (0, 1].
    shot_noise : bool
        Poisson photon (shot) noise.
    dark_current_e_per_s, exposure_time_s : float
        Dark electrons (Poisson) = rate [electrons/s] x time [s].
    full_well_e : float or None
        Saturation [electrons].
    read_noise_e : float
        Gaussian read noise [electrons RMS].
    gain_e_per_count : float
        Conversion gain [electrons per count (ADU)].
    black_level : float
        Offset added to the counts [ADU].
    gaussian_noise_percent : float
        White Gaussian noise with sigma = this percentage of ``peak`` [counts], as in
        tomographic PIV studies; the same sigma on every image of a set.
    peak : float or None
        Reference of ``gaussian_noise_percent`` [counts]; default the noise-free peak count
        of the whole set of images (``exposure * QE * scene_peak / gain``).
    bit_depth : int or None
        8, 10, 12, 14 or 16; rounds and clips to the ADC range.
    """

    exposure: float | None = None
    peak_photons: float | None = None
    illumination_time_s: float | None = None
    photometry: str = "auto"
    quantum_efficiency: float = 1.0
    shot_noise: bool = False
    dark_current_e_per_s: float = 0.0
    exposure_time_s: float = 0.0
    full_well_e: float | None = None
    read_noise_e: float = 0.0
    gain_e_per_count: float = 1.0
    black_level: float = 0.0
    gaussian_noise_percent: float = 0.0
    peak: float | None = None
    bit_depth: int | None = None

    def __post_init__(self):
        def nonneg(name):
            v = getattr(self, name)
            if not (isinstance(v, numbers.Real) and not isinstance(v, bool) and math.isfinite(v) and v >= 0):
                raise ConfigError(f"sensor: parameter '{name}' must be a finite number >= 0, got {v!r}.")

        given = [k for k in ("exposure", "peak_photons", "illumination_time_s") if getattr(self, k) is not None]
        if len(given) > 1:
            raise ConfigError(f"sensor: give one of 'exposure', 'peak_photons' and 'illumination_time_s', not both "
                              f"({' and '.join(given)}).")
        if self.photometry not in PHOTOMETRY:
            raise ConfigError(f"sensor: parameter 'photometry' must be one of {', '.join(PHOTOMETRY)}, "
                              f"got {self.photometry!r}.")
        if self.illumination_time_s is not None and self.photometry == "image":
            raise ConfigError("sensor: 'illumination_time_s' gives photons from the power a pixel collects, which needs "
                              "photometry = 'aperture' (or 'auto'), not 'image'.")
        for name in ("exposure", "peak_photons", "illumination_time_s", "full_well_e", "peak"):
            if getattr(self, name) is not None:
                check_positive(name, getattr(self, name), owner="sensor")
        for name in ("dark_current_e_per_s", "exposure_time_s", "read_noise_e", "black_level", "gaussian_noise_percent"):
            nonneg(name)
        qe = self.quantum_efficiency
        if not (isinstance(qe, numbers.Real) and 0 < qe <= 1):
            raise ConfigError(f"sensor: parameter 'quantum_efficiency' must be in (0, 1], got {qe!r}.")
        check_positive("gain_e_per_count", self.gain_e_per_count, owner="sensor")
        if self.bit_depth is not None and self.bit_depth not in _BIT_DEPTHS:
            raise ConfigError(f"sensor: parameter 'bit_depth' must be one of {_BIT_DEPTHS} or None, got {self.bit_depth!r}.")
        if self.shot_noise and not given:
            raise ConfigError(
                "sensor: 'shot_noise' needs photon counts: give 'exposure' (photons per unit of the exposed "
                "quantity), 'peak_photons' or 'illumination_time_s'."
            )

    def to_dict(self) -> dict:
        return asdict(self)


def _model(model, kwargs) -> SensorModel:
    if model is None:
        return SensorModel(**kwargs)
    if not isinstance(model, SensorModel):
        raise ConfigError(f"sensor: 'model' must be a SensorModel or None, got {type(model).__name__}.")
    return SensorModel(**{**model.to_dict(), **kwargs}) if kwargs else model


def _image(image, what: str) -> np.ndarray:
    img = np.asarray(image, dtype=np.float64)
    if img.ndim != 2 or img.size == 0:
        raise ConfigError(f"{what}: image must be a non-empty 2D array, got shape {img.shape}.")
    if not np.all(np.isfinite(img)) or np.any(img < 0):
        raise ConfigError(f"{what}: image must be finite and >= 0 (a rendered irradiance).")
    return img


def resolve_exposure(model: SensorModel, scene_peak: float, *, wavelength_nm: float | None = None
                     ) -> tuple[float, float | None]:
    """The exposure and the Gaussian-noise reference a set of images is taken with.

    Parameters
    ----------
    model : SensorModel
    scene_peak : float
        Maximum of the exposed quantity over the whole set of images (rendered value, or
        collected power with aperture photometry), >= 0.
    wavelength_nm : float, optional
        The sheet's vacuum wavelength [nm]; needed with ``illumination_time_s``.

    Returns
    -------
    exposure : float
        Photons per pixel per unit of the exposed quantity: ``model.exposure``, else
        ``peak_photons / scene_peak`` (0 for an all-black set), else from
        ``illumination_time_s`` (:func:`mitpiv.photometry.photons_per_watt`), else 1.
    noise_peak_counts : float or None
        Reference of ``gaussian_noise_percent`` [counts]: ``model.peak``, else
        ``exposure * QE * scene_peak / gain``; None without Gaussian noise.
    """
    top = float(scene_peak)
    if not (math.isfinite(top) and top >= 0):
        raise ConfigError(f"sensor: 'scene_peak' must be a finite number >= 0 [render units], got {scene_peak!r}.")
    if model.exposure is not None:
        exposure = float(model.exposure)
    elif model.peak_photons is not None:
        exposure = model.peak_photons / top if top > 0 else 0.0
        if top == 0:
            _log.warning("sensor: every image of the set is black; peak_photons gives no exposure.")
    elif model.illumination_time_s is not None:
        from mitpiv.photometry import photons_per_watt

        if wavelength_nm is None:
            raise ConfigError("sensor: 'illumination_time_s' needs the light's wavelength: render with a laser_sheet "
                              "(its wavelength is in the image metadata) or pass wavelength_nm.")
        exposure = photons_per_watt(model.illumination_time_s, wavelength_nm)
    else:
        exposure = 1.0  # image values are photons already
    noise_peak = None
    if model.gaussian_noise_percent > 0:
        noise_peak = float(model.peak) if model.peak is not None else \
            exposure * model.quantum_efficiency * top / model.gain_e_per_count
    return exposure, noise_peak


#: Largest mean [electrons] drawn from the Poisson distribution; brighter pixels keep their
#: mean (the relative shot noise there is below 3e-8) and saturate at the full well.
POISSON_MAX_E = 1e15


def _counts(img: np.ndarray, m: SensorModel, rng: np.random.Generator, exposure: float,
            noise_peak: float | None) -> np.ndarray:
    mean_e = img * (exposure * m.quantum_efficiency)
    if m.shot_noise:
        # NumPy's Poisson sampler refuses means near 2**63 ("lam value too large"); far below
        # that the shot noise (sqrt(mean)/mean < 3e-8 at 1e15 e-) is negligible and the pixel
        # saturates at the full well or the ADC's top code anyway: such pixels keep their mean.
        big = mean_e > POISSON_MAX_E
        e = rng.poisson(np.minimum(mean_e, POISSON_MAX_E)).astype(np.float64)
        if big.any():
            e = np.where(big, mean_e, e)
    else:
        e = mean_e
    dark = m.dark_current_e_per_s * m.exposure_time_s
    if dark > 0:
        e = e + rng.poisson(dark, size=e.shape)
    if m.full_well_e is not None:
        e = np.minimum(e, m.full_well_e)
    if m.read_noise_e > 0:
        e = e + rng.normal(0.0, m.read_noise_e, size=e.shape)
    counts = e / m.gain_e_per_count + m.black_level
    if m.gaussian_noise_percent > 0:
        counts = counts + rng.normal(0.0, m.gaussian_noise_percent / 100.0 * noise_peak, size=counts.shape)
    if m.bit_depth is None:
        return counts
    top = 2 ** m.bit_depth - 1
    out = np.clip(np.rint(counts), 0, top)
    return out.astype(np.uint8 if m.bit_depth == 8 else np.uint16)


def apply_sensor(image, model: SensorModel | None = None, *, seed: int = 0, scene_peak: float | None = None,
                 etendue=None, wavelength_nm: float | None = None, **kwargs) -> np.ndarray:
    """Turn one rendered image into sensor counts.

    The image is the whole set of images unless ``scene_peak`` says otherwise: with
    ``peak_photons`` (and for the default reference of ``gaussian_noise_percent``) its own
    maximum is the peak. For the cameras and frames of one experiment use
    :func:`apply_sensor_set`, or pass the set's maximum as ``scene_peak``.

    Parameters
    ----------
    image : (H, W) array
        Rendered image (finite, >= 0) [render units].
    model : SensorModel, optional
        Sensor parameters; keyword arguments build one (``apply_sensor(img, bit_depth=8,
        gaussian_noise_percent=5)``) or override fields of ``model`` (e.g. an explicit
        ``exposure=`` or noise ``peak=``).
    seed : int
        Seed of the noise, in [0, 2**64) (NumPy's PCG64, ``np.random.default_rng(seed)``);
        the same seed gives the same image. :func:`mitpiv.streams.sensor_seed` derives one
        per camera and frame.
    scene_peak : float, optional
        Maximum of the exposed quantity over the set this image belongs to, >= the
        image's maximum; default the image's maximum.
    etendue : float or (H, W) array, optional
        The pixels' étendue (:func:`mitpiv.photometry.pixel_etendue` of the image's camera
        record): aperture photometry, the exposed quantity is ``image * etendue`` [W].
        Needed with ``photometry = "aperture"`` and ``illumination_time_s``; refused with
        ``photometry = "image"``.
    wavelength_nm : float, optional
        The sheet's wavelength [nm], for ``illumination_time_s``.

    Returns
    -------
    uint8 / uint16 array with ``bit_depth``, else float64 counts.
    """
    from mitpiv.streams import check_seed

    m = _model(model, kwargs)
    seed = check_seed(seed, upper=2**64)
    img = _image(image, "apply_sensor")
    if etendue is None and (m.photometry == "aperture" or m.illumination_time_s is not None):
        raise ConfigError("apply_sensor: aperture photometry needs the pixels' étendue: pass "
                          "etendue=mitpiv.photometry.pixel_etendue(meta['camera']), or use photometry = 'image'.")
    if etendue is not None:
        if m.photometry == "image":
            raise ConfigError("apply_sensor: photometry = 'image' exposes the rendered value; leave 'etendue' out, "
                              "or use photometry = 'aperture'.")
        g = np.asarray(etendue, dtype=np.float64)
        if g.shape not in ((), img.shape) or not (np.all(np.isfinite(g)) and np.all(g > 0)):
            raise ConfigError(f"apply_sensor: 'etendue' must be a positive number or an array of the image's shape "
                              f"{img.shape} [mm^2 sr or mm^2], got shape {np.shape(etendue)}.")
        img = img * g
    own = float(img.max())
    if scene_peak is None:
        scene_peak = own
    elif not (isinstance(scene_peak, numbers.Real) and math.isfinite(scene_peak) and scene_peak >= own):
        raise ConfigError(f"apply_sensor: 'scene_peak' must be the maximum over a set that holds this image, "
                          f">= its maximum {own!r}, got {scene_peak!r}.")
    exposure, noise_peak = resolve_exposure(m, scene_peak, wavelength_nm=wavelength_nm)
    return _counts(img, m, np.random.default_rng(seed), exposure, noise_peak)


def noise_free(model: SensorModel) -> SensorModel:
    """``model`` without photon, read or dark noise, black level, full well or quantisation: the
    light each pixel collects at the same exposure, in counts (what the optics alone deliver)."""
    return replace(model, shot_noise=False, read_noise_e=0.0, dark_current_e_per_s=0.0, black_level=0.0,
                   gaussian_noise_percent=0.0, bit_depth=None, full_well_e=None)


@dataclass(frozen=True)
class SensorSetResult:
    """Counts of a set of images and what they were taken with.

    Attributes
    ----------
    counts : dict {(camera_id, frame): (H, W) array}
        Sensor counts (uint8 / uint16 with ``bit_depth``, else float64), in input order.
    model : SensorModel
    exposure : float
        Photons per pixel per unit of the exposed quantity, the same for every image.
    scene_peak : float
        Maximum of the exposed quantity over the set.
    noise_peak_counts : float or None
        Reference peak of ``gaussian_noise_percent`` [counts] (sigma = X/100 of it).
    seed : int
        The experiment seed.
    seeds : dict {(camera_id, frame): int}
        The derived 64-bit noise seed of each image
        (:func:`mitpiv.streams.sensor_seed`); ``apply_sensor(image, model, seed=seeds[key],
        scene_peak=scene_peak)`` reproduces ``counts[key]``.
    degenerate : dict {(camera_id, frame): str}
        Images that carry no particle signal, with the reason (:func:`degenerate_counts`).
    photometry : str
        "aperture" (the exposed quantity is the collected power ``V G`` [W]) or "image"
        (the rendered value ``V``).
    etendue_axis : dict {camera_id: float}
        With aperture photometry, each camera's on-axis pixel étendue [mm^2 sr, or mm^2 for
        irradiance cameras] (:func:`mitpiv.photometry.axis_etendue`).
    """

    counts: dict
    model: SensorModel
    exposure: float
    scene_peak: float
    noise_peak_counts: float | None
    seed: int
    seeds: dict = field(default_factory=dict)
    degenerate: dict = field(default_factory=dict)
    photometry: str = "image"
    etendue_axis: dict = field(default_factory=dict)

    @property
    def exposure_units(self) -> str:
        """What ``exposure`` counts photons per."""
        return ("photons per W collected by a pixel (rendered value x pixel etendue)" if self.photometry == "aperture"
                else "photons per unit of rendered pixel value")

    def metadata(self, key) -> dict:
        """JSON-ready record of how image ``key`` was taken, for its file's metadata: the
        model's fields (as :meth:`SensorModel.to_dict`) and what was used with them,
        ``exposure_used_photons_per_unit`` (and its ``exposure_units``), ``photometry``,
        ``etendue_axis`` (this camera's, aperture photometry), ``scene_peak``,
        ``noise_peak_counts``, ``experiment_seed``, ``sensor_seed`` and ``stream``
        (purpose, camera, frame)."""
        cam, frame = key
        return {**self.model.to_dict(), "exposure_used_photons_per_unit": self.exposure,
                "exposure_units": self.exposure_units, "photometry": self.photometry,
                "etendue_axis": self.etendue_axis.get(cam),
                "scene_peak": self.scene_peak, "noise_peak_counts": self.noise_peak_counts,
                "experiment_seed": self.seed, "sensor_seed": self.seeds[key],
                "stream": {"purpose": "sensor", "camera": cam, "frame": frame}}


def degenerate_counts(counts: np.ndarray, signal_peak_counts: float, model: SensorModel) -> str | None:
    """Why an image of sensor counts carries no particle signal, or None when it does.

    Degenerate: every pixel has the same count (black, or saturated), or, with
    ``bit_depth``, the brightest noise-free signal is below half a count, so rounding leaves
    only noise. ``signal_peak_counts`` is ``exposure * QE * scene_peak / gain`` [counts].
    """
    c = np.asarray(counts)
    fix = ("raise the exposure: give 'exposure' (photons per unit of the exposed quantity: the rendered value, or "
           "with aperture photometry the watts a pixel collects; mitpiv sensor --exposure), 'peak_photons' "
           "(--peak-photons) or 'illumination_time_s' (--illumination-time)")
    if signal_peak_counts <= 0:
        return "the rendered image is black (no light reached this camera); no exposure can help: see the render"
    if model.bit_depth is not None and signal_peak_counts < 0.5:
        return (f"the brightest pixel's signal is {signal_peak_counts:.3g} counts (exposure x QE x scene peak / "
                f"gain), below half a count: rounding to {model.bit_depth} bits leaves no particle; {fix}")
    if c.size and c.min() == c.max():
        top = None if model.bit_depth is None else 2 ** model.bit_depth - 1
        if top is not None and c.max() == top:
            return (f"every pixel saturates at {top} counts ({model.bit_depth} bits); lower the exposure or "
                    f"peak_photons, or raise full_well_e / gain_e_per_count")
        return f"every pixel is {c.max()!r} counts (signal peak {signal_peak_counts:.3g} counts); {fix}"
    return None


def resolve_photometry(model: SensorModel, cameras: Mapping | None, camera_ids) -> tuple[str, dict]:
    """The photometry a set of images is exposed with, and each camera's pixel étendue.

    Parameters
    ----------
    model : SensorModel
    cameras : mapping {camera_id: camera record of the image metadata} or None
    camera_ids : the cameras of the set

    Returns
    -------
    ("aperture", {camera_id: (H, W) étendue}) or ("image", {}).

    Raises
    ------
    ConfigError
        "aperture" (or ``illumination_time_s``) with a camera that states no aperture or
        is not described; "auto" with a set that mixes cameras with and without an
        aperture; "image" with cameras that record different quantities (radiance and
        the plenoptic camera's irradiance).
    """
    from mitpiv.photometry import FIX, axis_etendue, pixel_etendue

    ids = sorted(set(camera_ids))
    m_aperture = model.photometry == "aperture" or model.illumination_time_s is not None
    if cameras is None:
        if m_aperture:
            raise ConfigError("sensor: aperture photometry needs each camera's record (its image metadata's "
                              "'camera'): pass cameras={camera_id: meta['camera']}, or use photometry = 'image'.")
        return "image", {}
    missing = [c for c in ids if c not in cameras]
    if missing:
        raise ConfigError(f"sensor: no camera record for camera(s) {missing}; pass cameras={{camera_id: "
                          f"meta['camera']}} for every camera of the set.")
    if model.photometry == "image":
        kinds = {c: str((cameras[c] or {}).get("pixel_value", "radiance")).split()[0] for c in ids}
        if len(set(kinds.values())) > 1:
            raise ConfigError(f"sensor: photometry = 'image' exposes the rendered values, but these cameras record "
                              f"different quantities ({kinds}): one exposure cannot serve both. Use photometry = "
                              f"'aperture' (each camera's pixel values times its pixels' étendue).")
        return "image", {}
    has = {c: axis_etendue(cameras[c]) is not None for c in ids}
    if not any(has.values()) and not m_aperture:
        return "image", {}
    lacking = [c for c in ids if not has[c]]
    if lacking:
        why = ("photometry = 'aperture'" if model.photometry == "aperture" else
               "illumination_time_s" if model.illumination_time_s is not None else
               f"cameras {[c for c in ids if has[c]]} state an aperture, so their counts follow it")
        raise ConfigError(f"sensor: camera(s) {lacking} have no aperture ({why}); {FIX}.")
    return "aperture", {c: pixel_etendue(cameras[c], camera_id=c) for c in ids}


#: Share of an image's pixels at the full well or the ADC's top code above which the sensor warns.
SATURATION_WARN_FRACTION = 0.01


def saturation_warning(image: np.ndarray, counts: np.ndarray, exposure: float, model: SensorModel) -> str | None:
    """Why an image of counts is saturated, or None: more than
    :data:`SATURATION_WARN_FRACTION` of its pixels reach the full well (noise-free
    electrons ``image * exposure * QE >= full_well_e``) or the ADC's top code
    (``2**bit_depth - 1``); the text names the share and the fix."""
    img = np.asarray(image)
    if not img.size:
        return None
    parts = []
    if model.full_well_e is not None:
        f = float(np.mean(img * (exposure * model.quantum_efficiency) >= model.full_well_e))
        if f > SATURATION_WARN_FRACTION:
            parts.append(f"{100 * f:.1f} % of the pixels reach the full well ({model.full_well_e:g} e-)")
    if model.bit_depth is not None:
        top = 2 ** model.bit_depth - 1
        f = float(np.mean(np.asarray(counts) >= top))
        if f > SATURATION_WARN_FRACTION:
            parts.append(f"{100 * f:.1f} % of the pixels are clipped at the ADC's top code {top} "
                         f"({model.bit_depth} bits)")
    if not parts:
        return None
    return (f"{' and '.join(parts)} (more than {100 * SATURATION_WARN_FRACTION:g} %): their intensities are lost; "
            f"lower the exposure or peak_photons, or raise full_well_e / gain_e_per_count / bit_depth")


def apply_sensor_set(images: Mapping, model: SensorModel | None = None, *, seed: int, progress=None,
                     on_degenerate: str = "warn", cameras: Mapping | None = None,
                     wavelength_nm: float | None = None, **kwargs) -> SensorSetResult:
    """Turn a set of rendered images (every camera and frame of an experiment) into counts
    with one scene-wide exposure and one independent noise stream per image.

    The set's maximum exposed value (``scene_peak``) fixes the exposure once (with
    ``peak_photons``) and the reference peak of ``gaussian_noise_percent``; so two cameras
    whose rendered images differ 3:1 keep a 3:1 mean count and see the same noise sigma,
    and with aperture photometry (``cameras`` given, :func:`resolve_photometry`) an f/4
    camera records 4 times the counts of an f/8 one.
    Image ``(camera, frame)`` takes its noise from
    ``np.random.default_rng(mitpiv.streams.sensor_seed(seed, camera, frame))``: independent
    of the other images, and unchanged when the set holds other cameras or frames.

    Parameters
    ----------
    images : mapping {(camera_id: str, frame: int): (H, W) array}
        Rendered images (finite, >= 0) [render units]; shapes may differ between cameras.
    model : SensorModel, optional
        Sensor parameters; keyword arguments build one or override its fields.
    seed : int
        The experiment seed, an integer in [0, 2**63).
    progress : None, bool or callable
        See :mod:`mitpiv.progress`.
    on_degenerate : "warn", "raise" or "ignore"
        What to do when images carry no particle signal (:func:`degenerate_counts`; all
        black, say, because no exposure was given): "warn" issues a
        :class:`~mitpiv.errors.MitpivWarning` naming them; "raise" raises
        :class:`ConfigError` when *every* image is degenerate (warns for some);
        "ignore" only records them in ``result.degenerate``.
    cameras : mapping {camera_id: dict}, optional
        Each camera's record of the image metadata (``meta["camera"]``), for aperture
        photometry (:func:`resolve_photometry`); without it the rendered values are exposed.
    wavelength_nm : float, optional
        The sheet's wavelength [nm] (``meta["illumination"][0]["wavelength_nm"]``), for
        ``illumination_time_s``.

    Returns
    -------
    SensorSetResult
        ``counts`` per key, and ``exposure``, ``scene_peak``, ``noise_peak_counts`` and the
        derived ``seeds``; ``result.metadata(key)`` is the record for the image's file.
    """
    from mitpiv import streams
    from mitpiv.progress import track

    m = _model(model, kwargs)
    seed = streams.check_seed(seed)
    if not isinstance(images, Mapping) or not images:
        raise ConfigError("apply_sensor_set: 'images' must be a non-empty mapping {(camera_id, frame): 2D array}, "
                          f"got {type(images).__name__} of length {len(images) if hasattr(images, '__len__') else '?'}.")
    arrays = {}
    for key, image in images.items():
        if not (isinstance(key, tuple) and len(key) == 2 and isinstance(key[0], str)
                and isinstance(key[1], numbers.Integral) and not isinstance(key[1], bool) and key[1] >= 0):
            raise ConfigError(f"apply_sensor_set: every key must be (camera_id: str, frame: int >= 0), got {key!r}.")
        arrays[(key[0], int(key[1]))] = _image(image, f"apply_sensor_set: image {key!r}")
    if len(arrays) != len(images):
        raise ConfigError("apply_sensor_set: two keys name the same (camera_id, frame).")
    photometry, etendue = resolve_photometry(m, cameras, [k[0] for k in arrays])
    for key in arrays:
        if key[0] in etendue:
            if etendue[key[0]].shape != arrays[key].shape:
                raise ConfigError(f"sensor: image {key!r} is {arrays[key].shape[::-1]} px but its camera record says "
                                  f"{etendue[key[0]].shape[::-1]}; pass the record of the camera that rendered it.")
            arrays[key] = arrays[key] * etendue[key[0]]
    scene_peak = max(float(a.max()) for a in arrays.values())
    exposure, noise_peak = resolve_exposure(m, scene_peak, wavelength_nm=wavelength_nm)
    if on_degenerate not in ("warn", "raise", "ignore"):
        raise ConfigError(f"apply_sensor_set: 'on_degenerate' must be 'warn', 'raise' or 'ignore', got {on_degenerate!r}.")
    counts, seeds, bad = {}, {}, {}
    for key in track(list(arrays), desc="sensor", progress=progress, unit="image"):
        seeds[key] = streams.sensor_seed(seed, *key)
        counts[key] = _counts(arrays[key], m, np.random.default_rng(seeds[key]), exposure, noise_peak)
        signal = exposure * m.quantum_efficiency * float(arrays[key].max()) / m.gain_e_per_count
        reason = degenerate_counts(counts[key], signal, m)
        if reason is not None:
            bad[key] = reason
        elif (sat := saturation_warning(arrays[key], counts[key], exposure, m)) is not None:
            warnings.warn(f"sensor: camera {key[0]!r} frame {key[1]}: {sat}.", MitpivWarning, stacklevel=2)
    if bad and on_degenerate != "ignore":
        first = next(iter(bad))
        text = (f"{len(bad)} of {len(arrays)} sensor image(s) carry no particle signal, e.g. camera {first[0]!r} "
                f"frame {first[1]}: {bad[first]}.")
        if on_degenerate == "raise" and len(bad) == len(arrays):
            raise ConfigError(f"sensor: {text}")
        warnings.warn(text, MitpivWarning, stacklevel=2)
    from mitpiv.photometry import axis_etendue

    return SensorSetResult(counts=counts, model=m, exposure=exposure, scene_peak=scene_peak,
                           noise_peak_counts=noise_peak, seed=seed, seeds=seeds, degenerate=bad, photometry=photometry,
                           etendue_axis={c: axis_etendue(cameras[c]) for c in etendue})


def sensor_mean_variance(signal_photons: float, model: SensorModel) -> tuple[float, float]:
    """Mean and variance of the counts for a uniform signal (before clipping/rounding).

    The photon-transfer relation: ``var = (QE S [shot] + D t) / g^2 + sigma_r^2 / g^2
    + (X/100 peak)^2``, ``mean = (QE S + D t) / g + black``; ``peak`` defaults to the
    noise-free signal ``QE S / g`` (the uniform image is the whole set).
    """
    qe_s = model.quantum_efficiency * signal_photons
    dark = model.dark_current_e_per_s * model.exposure_time_s
    g = model.gain_e_per_count
    var = ((qe_s if model.shot_noise else 0.0) + dark + model.read_noise_e**2) / g**2
    if model.gaussian_noise_percent > 0:
        peak = model.peak if model.peak is not None else qe_s / g
        var += (model.gaussian_noise_percent / 100.0 * peak) ** 2
    return (qe_s + dark) / g + model.black_level, var


def convolve_psf(image, kernel) -> np.ndarray:
    """Convolve an image with a (space-invariant) PSF kernel by FFT; same shape as ``image``.

    The kernel's centre pixel (index ``size // 2``) is the origin; energy leaving the image
    edge is lost, as on a real sensor. Negative round-off is clipped to zero. The FFTs use
    every core (``scipy.fft.set_workers``; the same values as one worker): a 2560^2 render
    of the demo's 5x oversampled cameras takes 0.18 s instead of 0.35 s.
    """
    from scipy import fft
    from scipy.signal import fftconvolve

    img = np.asarray(image, dtype=np.float64)
    k = np.asarray(kernel, dtype=np.float64)
    if img.ndim != 2 or k.ndim != 2:
        raise ConfigError(f"convolve_psf: image and kernel must be 2D, got {img.shape} and {k.shape}.")
    if k.shape[0] % 2 == 0 or k.shape[1] % 2 == 0:
        raise ConfigError(f"convolve_psf: kernel sides must be odd (a centre pixel), got {k.shape}.")
    with fft.set_workers(-1):
        out = fftconvolve(img, k, mode="same")
    return np.maximum(out, 0.0)


def decimated_convolve(fine, kernel, step: int, *, method: str = "auto") -> np.ndarray:
    """``convolve_psf(fine, kernel)[step // 2::step, step // 2::step]``, computing only the kept outputs.

    ``fine`` is ``(H step, W step)``; the result is ``(H, W)``: the convolution at the centre
    fine pixel of each coarse pixel, edges and negative-round-off clip as in
    :func:`convolve_psf` (zero padding: energy leaving the image is lost). Equal to that
    path within float64 round-off (tests/test_imaging.py: 1e-12 of the image peak).

    Index mapping, per axis (kernel length ``L`` odd, centre ``c = L // 2``, ``h = step // 2``,
    ``s = step``). ``convolve_psf`` ("same" mode) gives ``y[i] = sum_m x[m] k[i + c - m]``;
    the kept output is ``out[I] = y[s I + h]``. With ``m = s J + r`` (phase ``r = 0..s-1``,
    ``x_r[J] = x[s J + r]``), ``T = (c + h) // s`` and ``e = (c + h) % s``::

        out[I] = sum_r sum_J x_r[J] g_r[I - J + T],    g_r[u] = k[s u + e - r]  (u = 0..2T,
                                                        zero where the index leaves 0..L-1)

    i.e. the sum over phases of "same" convolutions of the coarse phase images with the
    odd, centred (``2T + 1``) phase kernels; in 2-D, ``s^2`` phases ``(r_y, r_x)``.

    Two strategies, chosen by a cost estimate when ``method="auto"``:

    - ``"direct"``: a Numba kernel that, per output row, sums ``x_r[J] g_r[I - J + T]`` over
      the *non-zero* fine pixels only (a particle image is mostly exact zeros): about
      ``nnz min(2 Ty + 1, H) min(2 Tx + 1, W)`` multiply-adds (``nnz`` non-zero fine
      pixels; ``2T + 1``, about ``ceil(L / s)``, the per-phase kernel support in coarse
      pixels), plus two passes over the fine image to find them. No FFT round-off; the summation order differs.
    - ``"fft"``: the polyphase FFT on the coarse grid, ``irfft2(sum_r rfft2(x_r) G_r)``
      on a ``My x Mx`` grid (``H + 2 Ty`` and ``W + 2 Tx`` rounded up to fast FFT sizes; no
      wrap-around), scipy.fft with every core. Cost about
      ``(1.5 s^2 + 1) My Mx log2(My Mx)`` butterfly operations: ``s^2`` image-phase
      transforms, ``s^2`` phase-kernel transforms at half cost (only ``2T + 1`` rows are
      non-zero, so the row pass is pruned) and one inverse. The full-resolution path does
      three transforms ``s^2`` times larger.

    ``"auto"`` takes the direct kernel when its multiply-adds are fewer than
    ``_DIRECT_PER_FFT_OP = 0.3`` times the FFT operations: a multiply-add of the direct
    kernel measured 1.6 (533^2 kernel) to 3.5 ns (79^2 kernel) against about 1 ns per FFT
    operation (2-core machine, 1000^2 camera at s = 5, bench/bench_optics.py). A 1000^2
    camera at s = 5 with 4e5 non-zero fine pixels takes the direct kernel for the f/2.8
    (79^2 fine px) kernel and the FFT for the f/16 (533^2) one.

    Hand-written because no library we use computes a decimated 2-D convolution:
    ``scipy.signal.upfirdn`` does polyphase up/down-sampling with a 1-D filter along one
    axis, which covers only a separable kernel (a PSF with aberrations is not, and an
    exact separable split of a general kernel needs its full SVD rank of 1-D passes).
    """
    from scipy import fft

    img = np.asarray(fine, dtype=np.float64)
    k = np.asarray(kernel, dtype=np.float64)
    if isinstance(step, bool) or int(step) != step or step < 1:
        raise ConfigError(f"decimated_convolve: 'step' must be a positive integer, got {step!r}.")
    s = int(step)
    if img.ndim != 2 or k.ndim != 2:
        raise ConfigError(f"decimated_convolve: image and kernel must be 2D, got {img.shape} and {k.shape}.")
    if k.shape[0] % 2 == 0 or k.shape[1] % 2 == 0:
        raise ConfigError(f"decimated_convolve: kernel sides must be odd (a centre pixel), got {k.shape}.")
    if img.shape[0] % s or img.shape[1] % s:
        raise ConfigError(f"decimated_convolve: the image {img.shape} is not a multiple of step {s}.")
    if method not in ("auto", "direct", "fft"):
        raise ConfigError(f"decimated_convolve: 'method' must be 'auto', 'direct' or 'fft', got {method!r}.")
    ny, nx = img.shape[0] // s, img.shape[1] // s
    g, ty, tx = _phase_kernels(k, s)
    my = fft.next_fast_len(ny + 2 * ty, real=True)
    mx = fft.next_fast_len(nx + 2 * tx, real=True)
    nnz = -1
    if method == "auto":
        fft_ops = (1.5 * s * s + 1.0) * my * mx * math.log2(max(my * mx, 2))
        kern = _decimate_kernels()
        counts = np.empty(img.shape[0], np.int64)
        kern["row_counts"](img, counts)
        nnz = int(counts.sum())
        direct_ops = nnz * min(2 * ty + 1, ny) * min(2 * tx + 1, nx)
        method = "direct" if direct_ops < _DIRECT_PER_FFT_OP * fft_ops else "fft"
    if method == "direct":
        kern = _decimate_kernels()
        if nnz < 0:
            counts = np.empty(img.shape[0], np.int64)
            kern["row_counts"](img, counts)
        indptr = np.zeros(img.shape[0] + 1, np.int64)
        np.cumsum(counts, out=indptr[1:])
        cols = np.empty(int(indptr[-1]), np.int64)
        vals = np.empty(int(indptr[-1]), np.float64)
        kern["row_fill"](img, indptr, cols, vals)
        out = np.zeros((ny, nx))
        kern["direct"](indptr, cols, vals, g, out)
        return np.maximum(out, 0.0)

    acc = np.zeros((my, mx // 2 + 1), np.complex128)
    with fft.set_workers(-1):
        gx = fft.rfft(g, n=mx, axis=-1)  # pruned: only 2ty+1 rows per phase
        for ry in range(s):
            # the s column phases of fine rows ry::s, as (s, ny, nx)
            ph = img[ry::s].reshape(ny, nx, s).transpose(2, 0, 1)
            spec = fft.rfft2(ph, s=(my, mx), axes=(-2, -1))
            acc += np.einsum("rij,rij->ij", spec, fft.fft(gx[ry], n=my, axis=-2))
        out = fft.irfft2(acc, s=(my, mx))
    return np.maximum(out[ty:ty + ny, tx:tx + nx], 0.0)


def _phase_kernels(k: np.ndarray, s: int) -> tuple[np.ndarray, int, int]:
    """Phase kernels ``g[ry, rx, u, v] = k[s u + ey - ry, s v + ex - rx]`` (zero outside ``k``),
    ``(s, s, 2 ty + 1, 2 tx + 1)``, with ``(ty, ey) = divmod(Ly // 2 + s // 2, s)`` and likewise
    ``tx, ex`` (:func:`decimated_convolve`'s index mapping)."""
    ly, lx = k.shape
    ty, ey = divmod(ly // 2 + s // 2, s)
    tx, ex = divmod(lx // 2 + s // 2, s)
    ay = s * np.arange(2 * ty + 1)[None, :] + ey - np.arange(s)[:, None]  # (s, 2ty+1)
    ax = s * np.arange(2 * tx + 1)[None, :] + ex - np.arange(s)[:, None]
    vy, vx = (ay >= 0) & (ay < ly), (ax >= 0) & (ax < lx)
    g = k[np.clip(ay, 0, ly - 1)[:, None, :, None], np.clip(ax, 0, lx - 1)[None, :, None, :]]
    g *= vy[:, None, :, None] & vx[None, :, None, :]
    return g, ty, tx


#: Direct multiply-adds per FFT butterfly operation at which :func:`decimated_convolve`
#: switches strategy (measured; see its docstring).
_DIRECT_PER_FFT_OP = 0.3
_DECIMATE = {}


def _decimate_kernels() -> dict:
    """Numba kernels of :func:`decimated_convolve`'s direct strategy (compiled on first use)."""
    if _DECIMATE:
        return _DECIMATE
    from mitpiv._numba import numba

    nb = numba()

    @nb.njit(parallel=True, cache=True)
    def row_counts(img, counts):
        """Non-zero pixels of each row of ``img``."""
        for m in nb.prange(img.shape[0]):
            c = 0
            for n in range(img.shape[1]):
                if img[m, n] != 0.0:
                    c += 1
            counts[m] = c

    @nb.njit(parallel=True, cache=True)
    def row_fill(img, indptr, cols, vals):
        """CSR columns and values of ``img``'s non-zero pixels (rows from ``indptr``)."""
        for m in nb.prange(img.shape[0]):
            p = indptr[m]
            for n in range(img.shape[1]):
                v = img[m, n]
                if v != 0.0:
                    cols[p] = n
                    vals[p] = v
                    p += 1

    @nb.njit(parallel=True, cache=True)
    def direct(indptr, cols, vals, g, out):
        """``out[I, Jx'] += x[s J + ry, s Jx + rx] g[ry, rx, I - J + ty, Jx' - Jx + tx]`` over
        the CSR non-zeros of ``x`` (parallel over output rows: no races)."""
        ny, nx = out.shape
        s = g.shape[0]
        wy, wx = g.shape[2], g.shape[3]
        ty, tx = wy // 2, wx // 2
        for i in nb.prange(ny):
            for u in range(wy):
                jy = i + ty - u
                if jy < 0 or jy >= ny:
                    continue
                for ry in range(s):
                    m = s * jy + ry
                    for p in range(indptr[m], indptr[m + 1]):
                        n = cols[p]
                        jx = n // s
                        gr = g[ry, n - s * jx, u]
                        lo = max(0, jx - tx)
                        hi = min(nx - 1, jx + tx)
                        v = vals[p]
                        w = lo - jx + tx
                        for j in range(lo, hi + 1):
                            out[i, j] += v * gr[w]
                            w += 1

    _DECIMATE.update(row_counts=row_counts, row_fill=row_fill, direct=direct)
    return _DECIMATE


# ---------------------------------------------------------------------- PSF in rendering
_PSF_MODES = ("none", "fft", "jitter")


@dataclass(frozen=True)
class RenderPSF:
    """The diffraction/aberration PSF a camera applies to its rendered image.

    ``mode="fft"``: space invariant. The camera renders its film ``oversample`` times finer
    (odd, so a pixel centre is a fine-pixel centre) with a tent filter, which keeps each
    particle's sub-pixel position to first order; :meth:`apply` convolves that image with
    the PSF integrated over a whole pixel and sampled at the fine spacing, and keeps the
    pixel centres. The error falls as ``1 / oversample^2``.
    ``mode="jitter"``: the camera displaces each ray's film position by an offset drawn from
    the PSF (camera tracing: ``x - delta``; particle tracing: ``x + delta``), and the box
    filter integrates over pixels. The PSF may vary over the field: ``defocus_corner_waves``
    adds defocus growing as ``(h / h_corner)^2`` (field curvature), tabulated at
    ``field_levels`` heights evenly spaced in ``h^2`` and mixed linearly between them.
    Tables are sampled at ``pixel / table_oversample``.

    In both modes the PSF window holds ``1 - energy_tolerance`` of the light and is
    renormalised to 1, so the PSF moves light but neither adds nor removes any.
    """

    mode: str
    f_number: float
    pixel_pitch_um: float
    wavelength_nm: float = 532.0
    magnification: float | None = None
    zernike_coefficients: tuple = ()  # ((noll index, waves RMS), ...)
    defocus_corner_waves: float = 0.0
    energy_tolerance: float = 1e-3
    oversample: int = 5
    table_oversample: int = 8
    field_levels: int = 16

    def __post_init__(self):
        if self.mode not in _PSF_MODES:
            raise ConfigError(f"psf: parameter 'psf' must be one of {_PSF_MODES}, got {self.mode!r}.")
        if self.mode == "fft" and self.defocus_corner_waves != 0.0:
            raise ConfigError(
                "psf: 'psf_defocus_corner_waves' makes the PSF vary over the field; the FFT mode "
                "is space invariant. Use psf='jitter'."
            )
        for name in ("oversample", "table_oversample", "field_levels"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ConfigError(f"psf: parameter '{name}' must be a positive integer, got {v!r}.")
        if self.oversample % 2 == 0:
            raise ConfigError(f"psf: parameter 'psf_oversample' must be odd (pixel centres on fine-pixel centres), got {self.oversample}.")
        if self.field_levels < 2 and self.defocus_corner_waves != 0.0:
            raise ConfigError("psf: 'psf_field_levels' must be >= 2 with a field-dependent PSF.")
        # Build what the mode uses once (raises ConfigError for bad optics); cached for renders.
        if self.mode == "fft":
            _ = self.fft_kernel
        elif self.mode == "jitter":
            _ = self.jitter_tables

    def kernel_at(self, field_fraction_sq: float, *, pitch_um: float) -> np.ndarray:
        """Window-normalised PSF integrated over cells of ``pitch_um``, at field height^2 fraction."""
        from mitpiv.physics.psf import psf

        coefs = dict(self.zernike_coefficients)
        return psf(f_number=self.f_number, pixel_pitch_um=pitch_um, wavelength_nm=self.wavelength_nm,
                   magnification=self.magnification, zernike_coefficients=coefs,
                   defocus_waves=self.defocus_corner_waves * field_fraction_sq,
                   energy_tolerance=self.energy_tolerance, normalize="window")

    @property
    def fft_kernel(self) -> np.ndarray:
        """PSF integrated over a whole pixel, sampled every ``pixel / oversample`` (read-only;
        shared by equal PSFs, e.g. every camera and frame of a scene)."""
        return _fft_kernel(self)

    def _build_fft_kernel(self) -> np.ndarray:
        from scipy.signal import fftconvolve

        s = self.oversample
        fine = self.kernel_at(0.0, pitch_um=self.pixel_pitch_um / s)
        return fftconvolve(fine, np.ones((s, s)), mode="full")

    def apply(self, fine_image) -> np.ndarray:
        """FFT mode: oversampled render (H s, W s) -> PSF-convolved image (H, W): the
        convolution at the pixel centres only (:func:`decimated_convolve`)."""
        s = self.oversample
        img = np.asarray(fine_image, dtype=np.float64)
        if img.shape[0] % s or img.shape[1] % s:
            raise ConfigError(f"psf: the rendered image {img.shape} is not {s} times the camera resolution.")
        return decimated_convolve(img, self.fft_kernel, s) / (s * s)

    @property
    def jitter_tables(self) -> tuple[np.ndarray, int, int]:
        """(cell probabilities (levels, S, S), S, levels) for the jitter sampler (read-only, shared)."""
        return _jitter_tables(self)

    def _build_jitter_tables(self) -> tuple[np.ndarray, int, int]:
        levels = self.field_levels if self.defocus_corner_waves != 0.0 else 1
        q = self.pixel_pitch_um / self.table_oversample
        ks = [self.kernel_at(k / max(levels - 1, 1), pitch_um=q) for k in range(levels)]
        size = max(k.shape[0] for k in ks)
        out = np.zeros((levels, size, size))
        for i, k in enumerate(ks):
            o = (size - k.shape[0]) // 2
            out[i, o:o + k.shape[0], o:o + k.shape[0]] = k / k.sum()
        return out, size, levels

    def to_dict(self) -> dict:
        d = asdict(self)
        d["zernike_coefficients"] = {f"noll{j}": c for j, c in self.zernike_coefficients}
        d["indexing"] = "noll"
        return d


@lru_cache(maxsize=32)
def _fft_kernel(psf: RenderPSF) -> np.ndarray:
    k = psf._build_fft_kernel()
    k.setflags(write=False)
    return k


@lru_cache(maxsize=32)
def _jitter_tables(psf: RenderPSF) -> tuple[np.ndarray, int, int]:
    tables, size, levels = psf._build_jitter_tables()
    tables.setflags(write=False)
    return tables, size, levels


# ---------------------------------------------------------------------- point images by table splatting
@dataclass(frozen=True)
class PointPSFTable:
    """Pixel-integrated images of a point source at sub-pixel offsets, for splatting.

    ``fine[a, b]`` is the PSF integrated over one whole pixel whose centre lies
    ``((b - c) / oversample, (a - c) / oversample)`` pixels from the point (``c`` the
    centre index), so the value of pixel ``(i, j)`` for a point at ``(u, v)`` is
    ``fine[c + s (j + 0.5 - v), c + s (i + 0.5 - u)]`` (``s = oversample``, rounded to the
    nearest fine sample: positions are quantised to ``1 / s`` px). Each point's
    ``window x window`` footprint is renormalised to 1 (the window holds the light, as in a
    PSF table of the SAPIV aberration study, Table 3.2).
    """

    fine: np.ndarray
    oversample: int
    window: int

    @classmethod
    def build(cls, *, f_number: float, pixel_pitch_um: float, magnification: float | None = None,
              spherical_waves: float = 0.0, wavelength_nm: float = 532.0, window: int = 5,
              oversample: int = 15) -> PointPSFTable:
        """Table of the Fourier-optics PSF (:func:`mitpiv.physics.psf.psf`, circular pupil,
        Zernike spherical aberration ``spherical_waves`` RMS) integrated over square pixels.

        window : odd footprint side [px]; oversample : odd number of fine samples per pixel.
        """
        from scipy.signal import fftconvolve

        from mitpiv.physics.psf import psf

        for name, v in (("window", window), ("oversample", oversample)):
            if isinstance(v, bool) or int(v) != v or v < 1 or v % 2 == 0:
                raise ConfigError(f"PointPSFTable: '{name}' must be an odd positive integer, got {v!r}.")
        s = int(oversample)
        size = (int(window) + 1) * s + 1
        pt = psf(f_number=f_number, pixel_pitch_um=pixel_pitch_um / s, wavelength_nm=wavelength_nm,
                 magnification=magnification, spherical_waves=spherical_waves, size_px=size, normalize="total")
        fine = fftconvolve(pt, np.ones((s, s)), mode="same")  # integral over a whole pixel
        fine = np.maximum(fine, 0.0)
        fine.setflags(write=False)
        return cls(fine=fine, oversample=s, window=int(window))

    @classmethod
    def from_kernel(cls, kernel, *, oversample: int = 15) -> PointPSFTable:
        """Table of a discrete pixel kernel (e.g. a PSF table printed in a paper): the point's
        light falls in the pixel holding it and is spread over its neighbours by ``kernel``
        (odd square, window = its side), whatever the sub-pixel position.

        kernel : (w, w) non-negative array with a positive sum (renormalised to 1 per point).
        """
        k = np.asarray(kernel, dtype=float)
        if k.ndim != 2 or k.shape[0] != k.shape[1] or k.shape[0] % 2 == 0:
            raise ConfigError(f"PointPSFTable.from_kernel: 'kernel' must be an odd square 2D array, got shape {k.shape}.")
        if not np.all(np.isfinite(k)) or np.any(k < 0) or k.sum() <= 0:
            raise ConfigError("PointPSFTable.from_kernel: 'kernel' must be finite, non-negative and sum to > 0.")
        if isinstance(oversample, bool) or int(oversample) != oversample or oversample < 1 or oversample % 2 == 0:
            raise ConfigError(f"PointPSFTable.from_kernel: 'oversample' must be an odd positive integer, got {oversample!r}.")
        s = int(oversample)
        fine = np.kron(k / k.sum(), np.ones((s, s)))  # block d of the footprint: every offset in that pixel
        fine.setflags(write=False)
        return cls(fine=fine, oversample=s, window=int(k.shape[0]))

    @classmethod
    def gaussian(cls, sigma_px: float, *, oversample: int = 9) -> PointPSFTable:
        """Table of a circular Gaussian of standard deviation ``sigma_px`` [px] integrated over
        square pixels (differences of the normal CDF, exact), window ``2 ceil(3 sigma) + 1``.

        oversample : positive number of fine samples per pixel.
        """
        from scipy.special import ndtr

        sigma_px = check_positive("sigma_px", sigma_px, owner="PointPSFTable.gaussian", unit="px")
        if isinstance(oversample, bool) or int(oversample) != oversample or oversample < 1:
            raise ConfigError(f"PointPSFTable.gaussian: 'oversample' must be a positive integer, got {oversample!r}.")
        window = 2 * int(math.ceil(3 * sigma_px)) + 1
        s = int(oversample)
        size = (window + 1) * s + 1
        t = (np.arange(size) - size // 2) / s  # pixel-centre offsets from the point [px]
        g = ndtr((t + 0.5) / sigma_px) - ndtr((t - 0.5) / sigma_px)
        fine = np.outer(g, g)
        fine.setflags(write=False)
        return cls(fine=fine, oversample=s, window=window)

    def peak(self) -> float:
        """The brightest pixel of one point centred on a pixel (its footprint sums to 1)."""
        _, _, v = self.footprints(np.array([[0.5, 0.5]]))
        return float(v.max())

    def footprints(self, uv_px) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(i0 (n,), j0 (n,), values (n, window, window)): each point's footprint, whose pixel
        ``[a, b]`` is image pixel ``(row j0 + a, column i0 + b)``; each footprint sums to 1."""
        uv = np.asarray(uv_px, dtype=float).reshape(-1, 2)
        s, h = self.oversample, self.window // 2
        c = self.fine.shape[0] // 2
        base = np.floor(uv).astype(np.int64)  # pixel holding the point
        frac = uv - base - 0.5  # offset from that pixel's centre, in [-0.5, 0.5)
        d = np.arange(-h, h + 1)
        ix = c + s * d[None, :] - np.rint(s * frac[:, 0:1]).astype(np.int64)
        iy = c + s * d[None, :] - np.rint(s * frac[:, 1:2]).astype(np.int64)
        vals = self.fine[iy[:, :, None], ix[:, None, :]]
        tot = vals.sum(axis=(1, 2), keepdims=True)
        vals = vals / np.where(tot > 0, tot, 1.0)
        return base[:, 0] - h, base[:, 1] - h, vals


def splat_points(uv_px, resolution, table: PointPSFTable, *, weights=None, dtype=np.float32) -> np.ndarray:
    """Image (H, W) of point sources at pixel positions ``uv_px`` (n, 2) (mitpiv convention:
    pixel ``i`` spans ``[i, i + 1)``), each of total energy ``weights`` (default 1), spread by
    ``table``; light falling outside the sensor is lost. Points with non-finite positions
    are skipped."""
    w, h = (int(v) for v in resolution)
    uv = np.asarray(uv_px, dtype=float).reshape(-1, 2)
    wt = np.ones(len(uv)) if weights is None else np.broadcast_to(np.asarray(weights, float), (len(uv),))
    ok = np.all(np.isfinite(uv), axis=1) & (uv[:, 0] > -table.window) & (uv[:, 0] < w + table.window) \
        & (uv[:, 1] > -table.window) & (uv[:, 1] < h + table.window)
    uv, wt = uv[ok], wt[ok]
    i0, j0, vals = table.footprints(uv)
    n = table.window
    cols = i0[:, None, None] + np.arange(n)[None, None, :]
    rows = j0[:, None, None] + np.arange(n)[None, :, None]
    cols, rows = np.broadcast_to(cols, vals.shape), np.broadcast_to(rows, vals.shape)
    inside = (cols >= 0) & (cols < w) & (rows >= 0) & (rows < h)
    flat = (rows * w + cols)[inside]
    img = np.bincount(flat, weights=(vals * wt[:, None, None])[inside], minlength=w * h)
    return img.reshape(h, w).astype(dtype)


def point_images(cameras, points_mm, table: PointPSFTable, *, peak: float, factors=None) -> list[np.ndarray]:
    """Noise-free images (H, W) float64, one per camera, of the points ``points_mm`` (n, 3)
    [world mm]: each point projected by the camera (``project``) and splatted with ``table``
    (:func:`splat_points`), scaled so that a point centred on a pixel peaks at
    ``peak * factor`` (``factors``: one per camera, default 1)."""
    scale = peak / table.peak()
    factors = [1.0] * len(cameras) if factors is None else factors
    out = []
    for cam, f in zip(cameras, factors, strict=True):
        uv = cam.project(points_mm)
        out.append(splat_points(uv, cam.resolution, table, dtype=np.float64) * (scale * float(f)))
    return out
