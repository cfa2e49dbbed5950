"""Camera mappings world [mm] -> pixels, with the derivative reconstruction needs.

Every mapping offers the camera contract (:class:`mitpiv.physics.camera.Camera`):
``project(p_world) -> (..., 2)`` pixels (mitpiv convention: pixel ``(i, j)`` spans
``[i, i+1)``, so its centre is at ``i + 0.5``), ``in_front`` and ``visible`` (in front
and on the sensor), ``jacobian(p_world) -> (..., 2, 3)`` = d(pixel)/d(world), and
``to_dict``/``from_dict``. Mappings:

- :class:`PinholeMapping`: a :class:`PinholeCamera` (pinhole + Brown-Conrady), either the
  true model from EXR metadata (:func:`mapping_from_metadata`, "perfect calibration") or
  one fitted by :func:`mitpiv.reconstruct.calibrate`; every method is the camera's own.
- :class:`PolynomialMapping`: Soloff's polynomial, cubic in x and y and quadratic in z (19
  terms per image coordinate; or the full cubic, 20 terms), fitted by least squares on
  normalised coordinates, or a user's table (:func:`mitpiv.io.read_polynomial_table`).
"""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np

from mitpiv.errors import ConfigError
from mitpiv.physics.camera import PinholeCamera, on_sensor
from mitpiv.physics.camera_fit import CUBIC_TERMS, SOLOFF_TERMS, monomials

__all__ = ["CameraMapping", "PinholeMapping", "PolynomialMapping", "mapping_from_metadata", "mappings_from_calibration",
           "SOLOFF_TERMS"]



class CameraMapping(ABC):
    """Abstract base: subclasses implement ``project``, ``jacobian`` and ``to_dict``."""

    resolution: tuple[int, int] | None = None

    @abstractmethod
    def project(self, p_world) -> np.ndarray:
        """World points (..., 3) [mm] -> pixels (..., 2)."""

    @abstractmethod
    def jacobian(self, p_world) -> np.ndarray:
        """d(pixel)/d(world), (..., 2, 3) [px/mm]."""

    @abstractmethod
    def to_dict(self) -> dict:
        """JSON-ready description with a ``"type"``; :meth:`from_dict` restores it."""

    @classmethod
    def from_dict(cls, d: dict) -> CameraMapping:
        """The mapping of a :meth:`to_dict` description (any subclass, by its ``"type"``)."""
        kinds = {"pinhole": PinholeMapping, "soloff_polynomial": PolynomialMapping}
        kind = d.get("type") if isinstance(d, dict) else None
        if kind not in kinds:
            raise ConfigError(f"CameraMapping.from_dict: 'type' must be one of {sorted(kinds)}, got {kind!r}.")
        return kinds[kind]._from_dict(d)

    def in_front(self, p_world) -> np.ndarray:
        """Whether world points (..., 3) lie in front of the camera (all True for a mapping
        that does not know where its camera is, such as a fitted polynomial)."""
        return np.ones(np.shape(p_world)[:-1], dtype=bool)

    def visible(self, p_world) -> np.ndarray:
        """Points (..., 3) :meth:`in_front` whose projection lands on the sensor
        ``[0, W) x [0, H)`` (only the first test when the mapping has no resolution)."""
        front = self.in_front(p_world)
        if self.resolution is None:
            return front
        with np.errstate(invalid="ignore", over="ignore"):
            return front & on_sensor(self.project(p_world), self.resolution)

    def residuals(self, pixels, p_world) -> np.ndarray:
        """Reprojection error vectors [px]: project(world) - pixels."""
        return self.project(p_world) - np.asarray(pixels, dtype=float)

    def rms_error(self, pixels, p_world) -> float:
        r = self.residuals(pixels, p_world)
        return float(np.sqrt(np.mean(np.sum(r * r, axis=-1))))


class PinholeMapping(CameraMapping):
    """The mapping of a :class:`PinholeCamera` (pinhole + Brown-Conrady, thin lens or not):
    ``project``, ``in_front``, ``visible`` and ``jacobian`` are the camera's own."""

    def __init__(self, camera: PinholeCamera):
        if not isinstance(camera, PinholeCamera):
            raise ConfigError(f"PinholeMapping: 'camera' must be a PinholeCamera, got {type(camera).__name__}.")
        self.camera = camera
        self.resolution = camera.resolution

    def project(self, p_world) -> np.ndarray:
        return self.camera.project(p_world)

    def in_front(self, p_world) -> np.ndarray:
        """Points in front of the pinhole (camera-frame z > 0); the projection of a point
        behind it lands on the image mirrored, so reconstructions must leave it out."""
        return self.camera.in_front(p_world)

    def visible(self, p_world) -> np.ndarray:
        return self.camera.visible(p_world)

    def jacobian(self, p_world) -> np.ndarray:
        return self.camera.jacobian(p_world)

    def to_dict(self) -> dict:
        return {"type": "pinhole", "camera": self.camera.to_dict()}

    @classmethod
    def _from_dict(cls, d: dict) -> PinholeMapping:
        return cls(PinholeCamera.from_dict(d["camera"]))


def mapping_from_metadata(meta: dict) -> PinholeMapping:
    """The true mapping of a rendered image from its EXR metadata (``meta["camera"]``, or
    that entry itself), read by :func:`mitpiv.io.camera_from_metadata`.

    Raises
    ------
    ConfigError
        The image comes from a camera that is not a pinhole (a plenoptic raw image needs
        the light-field methods).
    FileFormatError
        The metadata holds no usable camera (see :func:`~mitpiv.io.camera_from_metadata`).
    """
    from mitpiv.io.camera import camera_from_metadata

    cam = meta.get("camera", meta) if isinstance(meta, dict) else meta
    if isinstance(cam, dict) and cam.get("type") == "plenoptic":
        raise ConfigError(
            "mapping_from_metadata: the metadata has no pinhole camera model but a plenoptic one; a raw "
            "plenoptic image needs the light-field methods (mitpiv.reconstruct.plenoptic_volume, drt_mart)."
        )
    camera = camera_from_metadata(meta)
    if not isinstance(camera, PinholeCamera):
        raise ConfigError(
            f"mapping_from_metadata: the metadata has no pinhole camera model but a {type(camera).__name__}; "
            f"was the image rendered by a distorted_pinhole sensor?"
        )
    return PinholeMapping(camera)


def mappings_from_calibration(path, *, names=None, resolution=None, pixel_pitch_um: float | None = None,
                              max_residual_px: float | None = None) -> list[CameraMapping]:
    """Reconstruction mappings from a user's calibration table (:mod:`mitpiv.io.calibration_tables`).

    A polynomial table gives :class:`PolynomialMapping` s (the polynomial itself, no
    approximation); a DLT table :class:`PinholeMapping` s (the DLT as a square-pixel camera,
    refused beyond ``max_residual_px``); an OpenCV file one :class:`PinholeMapping`.

    Parameters
    ----------
    path : str or Path
        The calibration file.
    names : list of str, optional
        The cameras to take, in this order (e.g. the images' ``sensor_id`` s); default every
        camera of the table in its order.
    resolution, pixel_pitch_um : optional
        Image size [px] and pixel pitch [um] where the file does not hold them (a DLT's
        camera needs both; a polynomial needs neither).
    max_residual_px : float, optional
        DLT only: see :func:`mitpiv.io.read_dlt_cameras`.
    """
    from mitpiv.io.calibration_tables import (
        calibration_table_format,
        read_dlt_cameras,
        read_dlt_table,
        read_polynomial_table,
        select_camera,
    )
    from mitpiv.io.opencv import read_opencv_camera

    fmt = calibration_table_format(path)
    if fmt is None:
        raise ConfigError(f"mappings_from_calibration: {str(path)!r} is not a calibration file mitpiv reads (OpenCV "
                          f".yml / .xml / .json, or a DLT or polynomial table .csv / .json).")
    if fmt == "opencv":
        return [PinholeMapping(read_opencv_camera(path, pixel_pitch_um=pixel_pitch_um or 10.0, resolution=resolution,
                                                  pose="require"))]
    records = (read_dlt_table if fmt == "dlt" else read_polynomial_table)(path)[0]
    chosen = records if names is None else [select_camera(records, n, path=path) for n in names]
    if fmt == "polynomial":
        return [PolynomialMapping(r["coefficients"], r["centre_mm"], r["scale_mm"],
                                  resolution or ((r["image_width"], r["image_height"]) if r.get("image_width") else None),
                                  terms=r["terms"]) for r in chosen]
    kw = {} if max_residual_px is None else {"max_residual_px": max_residual_px}
    return [PinholeMapping(read_dlt_cameras(path, camera=r["name"], resolution=resolution,
                                            pixel_pitch_um=pixel_pitch_um or 10.0, **kw)[0]) for r in chosen]


class PolynomialMapping(CameraMapping):
    """Soloff polynomial mapping on normalised coordinates ``q = (p - centre) / scale``:
    ``(u, v) = coefficients @ monomials(q)``, with the 19 terms of :data:`SOLOFF_TERMS`
    (default) or the 20 of :data:`~mitpiv.physics.camera_fit.CUBIC_TERMS`."""

    def __init__(self, coefficients, centre_mm, scale_mm, resolution=None, *, terms=SOLOFF_TERMS):
        terms = tuple(tuple(int(e) for e in t) for t in terms)
        if terms not in (SOLOFF_TERMS, CUBIC_TERMS):
            raise ConfigError(f"PolynomialMapping: 'terms' must be Soloff's 19 {list(SOLOFF_TERMS)} or the 20 of the "
                              f"full cubic (those and z^3), got {list(terms)}.")
        self.terms = terms
        # C order whatever the source (a least-squares fit hands back a Fortran-ordered array):
        # BLAS picks its kernel, hence its summation order, by memory layout, so a mapping read
        # back from JSON must hold the same layout to project bit for bit as the fitted one
        self.coefficients = np.ascontiguousarray(np.asarray(coefficients, dtype=float).reshape(2, len(terms)))
        self.centre_mm = np.asarray(centre_mm, dtype=float).reshape(3)
        self.scale_mm = np.asarray(scale_mm, dtype=float).reshape(3)
        self.resolution = None if resolution is None else tuple(int(v) for v in resolution)

    @staticmethod
    def design(q, terms=SOLOFF_TERMS) -> np.ndarray:
        """Monomials of normalised coordinates q (..., 3) -> (..., len(terms))."""
        return monomials(q, terms)

    @staticmethod
    def normalisation(p_world) -> tuple[np.ndarray, np.ndarray]:
        """(centre, half-range) of the points per axis (half-range 1 where they do not spread)."""
        w = np.asarray(p_world, dtype=float).reshape(-1, 3)
        centre = 0.5 * (w.max(axis=0) + w.min(axis=0))
        scale = 0.5 * (w.max(axis=0) - w.min(axis=0))
        scale[scale == 0] = 1.0
        return centre, scale

    @classmethod
    def fit(cls, pixels, p_world, *, resolution=None, terms=SOLOFF_TERMS) -> PolynomialMapping:
        """Least-squares fit (the caller checks the marker set; see :func:`calibrate`)."""
        w = np.asarray(p_world, dtype=float).reshape(-1, 3)
        px = np.asarray(pixels, dtype=float).reshape(-1, 2)
        centre, scale = cls.normalisation(w)
        coef, *_ = np.linalg.lstsq(cls.design((w - centre) / scale, terms), px, rcond=None)
        return cls(coef.T, centre, scale, resolution, terms=terms)

    def project(self, p_world) -> np.ndarray:
        q = (np.asarray(p_world, dtype=float) - self.centre_mm) / self.scale_mm
        return self.design(q, self.terms) @ self.coefficients.T

    def jacobian(self, p_world) -> np.ndarray:
        q = (np.asarray(p_world, dtype=float) - self.centre_mm) / self.scale_mm
        cols = []
        for axis in range(3):
            terms = []
            for e in self.terms:
                if e[axis] == 0:
                    terms.append(np.zeros(q.shape[:-1]))
                    continue
                val = e[axis] * q[..., axis] ** (e[axis] - 1)
                for other in range(3):
                    if other != axis:
                        val = val * q[..., other] ** e[other]
                terms.append(val)
            cols.append(np.stack(terms, axis=-1) @ self.coefficients.T / self.scale_mm[axis])
        return np.stack(cols, axis=-1)

    def to_dict(self) -> dict:
        return {"type": "soloff_polynomial", "terms": [list(t) for t in self.terms],
                "coefficients": self.coefficients.tolist(), "centre_mm": self.centre_mm.tolist(),
                "scale_mm": self.scale_mm.tolist(), "resolution": None if self.resolution is None else list(self.resolution)}

    @classmethod
    def _from_dict(cls, d: dict) -> PolynomialMapping:
        terms = tuple(tuple(t) for t in d.get("terms", SOLOFF_TERMS))
        if terms not in (SOLOFF_TERMS, CUBIC_TERMS):
            raise ConfigError(f"PolynomialMapping.from_dict: 'terms' {list(terms)} are not Soloff's 19 terms "
                              f"{list(SOLOFF_TERMS)} nor the full cubic's 20.")
        return cls(d["coefficients"], d["centre_mm"], d["scale_mm"], d.get("resolution"), terms=terms)
