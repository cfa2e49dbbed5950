"""One reconstruction entry point for rendered images with their metadata: the camera-image
methods (:func:`~mitpiv.reconstruct.reconstruct_volume`) and the plenoptic ones (volumetric
refocus of each decoded light field, fused over cameras; DRT-MART of one raw image), shared
by the CLI and the experiment runner."""

from __future__ import annotations

import numpy as np

from mitpiv.errors import ConfigError
from mitpiv.grid import VoxelGrid
from mitpiv.progress import Progress
from mitpiv.reconstruct.tomo import TOMO_METHODS, reconstruct_volume

RECONSTRUCT_METHODS = TOMO_METHODS + ("plenoptic", "drt-mart")
_NO_INDEX = np.zeros(0, dtype=np.int64)  # DRT-MART's cache entry has no active-voxel index


def reconstruction_cost_of(metas, grid: VoxelGrid, method: str, *, iterations: int, rays_per_pixel: int = 16):
    """:class:`mitpiv.costs.Cost` of :func:`reconstruct_images` on images with this metadata:
    DRT-MART by its ray-traced weights (:func:`~mitpiv.reconstruct.plenoptic.drt_cost`, the
    first image's plenoptic camera), every other method by its voxels and images
    (:func:`mitpiv.costs.reconstruction_cost`)."""
    from mitpiv import costs

    if method == "drt-mart" and metas:
        from mitpiv.lightfield.decode import optics_from_metadata
        from mitpiv.reconstruct.plenoptic import drt_cost

        cam = optics_from_metadata(metas[0])
        if cam is not None:
            return drt_cost(cam, grid, rays_per_pixel=rays_per_pixel, iterations=iterations)
    return costs.reconstruction_cost(grid.n_voxels, n_images=len(metas), iterations=iterations, method=method)


def reconstruct_images(images, metas, grid: VoxelGrid, method: str = "mart", *, whites=None, iterations: int = 5,
                       mu: float = 1.0, weights: str = "circle", interpolation: str = "linear",
                       preprocess: float | None = None, smooth_px: float = 0.0, floor_rel: float = 0.0,
                       combine: str = "multiplicative",
                       threshold_k: float | None = 3.0,
                       rays_per_pixel: int = 16, fuse_normalise: str = "histogram", min_coverage: float | None = None,
                       progress: Progress = None, cache=None, mappings=None) -> tuple[np.ndarray, dict]:
    """Reconstruct a volume from the images of one frame and their EXR metadata.

    method : one of :data:`RECONSTRUCT_METHODS`. "plenoptic": each raw image decoded (its
        camera from the metadata, devignetted by ``whites`` when given), refocused onto
        ``grid`` (``combine``: additive or multiplicative), the volumes of several cameras
        fused (:func:`~mitpiv.reconstruct.fuse`, ``fuse_normalise``); "drt-mart": one raw
        image, dense-ray-tracing MART (``rays_per_pixel``, ``min_coverage``). Other methods: :func:`reconstruct_volume`.
    progress : None, bool or callable
        Passed to the method (planes, iterations); see :mod:`mitpiv.progress`.
    cache : :class:`~mitpiv.reconstruct.tomo.WeightCache`, optional
        MART/SMART weights, or DRT-MART's ray-traced matrix, shared by the frames of one
        experiment (same cameras and grid).
    mappings : list of CameraMapping, optional
        Tomographic methods: one mapping per image (e.g. a user's calibration,
        :func:`~mitpiv.reconstruct.mapping.mappings_from_calibration`) instead of the true
        cameras of the metadata.

    Returns (volume, info).
    """
    if method in TOMO_METHODS:
        from mitpiv.reconstruct.mapping import mapping_from_metadata

        maps = []
        for k, m in enumerate(metas):
            if (m.get("camera") or {}).get("type") == "plenoptic":
                raise ConfigError(f"reconstruct: image {k} comes from a plenoptic camera; method {method!r} needs "
                                  f"pinhole cameras. Use method 'plenoptic' or 'drt-mart'.")
            if mappings is None:
                maps.append(mapping_from_metadata(m))
        if mappings is not None:
            if len(mappings) != len(images):
                raise ConfigError(f"reconstruct: {len(mappings)} camera mapping(s) for {len(images)} image(s); give one "
                                  f"calibration per image.")
            maps = list(mappings)
        return reconstruct_volume(images, maps, grid, method, iterations=iterations, mu=mu, weights=weights,
                                  interpolation=interpolation, preprocess=preprocess, smooth_px=smooth_px,
                                  floor_rel=floor_rel,
                                  combine=combine,
                                  threshold_k=threshold_k, progress=progress, cache=cache)
    if method not in RECONSTRUCT_METHODS:
        raise ConfigError(f"reconstruct: method={method!r} is not one of {RECONSTRUCT_METHODS}.")
    from mitpiv.lightfield import decode
    from mitpiv.lightfield.decode import optics_from_metadata
    from mitpiv.reconstruct.plenoptic import drt_mart, drt_weights, fuse, plenoptic_volume

    cams = [optics_from_metadata(m) for m in metas]
    if any(c is None for c in cams):
        bad = [k for k, c in enumerate(cams) if c is None]
        raise ConfigError(f"reconstruct: method {method!r} needs raw images of plenoptic sensors; image(s) {bad} "
                          f"carry no plenoptic camera metadata. Use a tomographic method for pinhole cameras.")
    if method == "drt-mart":
        if len(images) != 1:
            raise ConfigError(f"reconstruct: drt-mart takes one raw image, got {len(images)}.")
        matrix, t_weights = None, 0.0
        if cache is not None:  # the frames of an experiment share the camera and the grid
            import json
            import time

            key = ("drt-mart", json.dumps(cams[0].to_dict(), sort_keys=True, default=str),
                   json.dumps(grid.to_dict(), sort_keys=True), int(rays_per_pixel))
            hit = cache.get(key, _NO_INDEX)
            if hit is None:
                t0 = time.perf_counter()
                matrix = drt_weights(cams[0], grid, rays_per_pixel=rays_per_pixel, progress=progress)
                t_weights = time.perf_counter() - t0
                cache.put(key, _NO_INDEX, [matrix])
            else:
                matrix = hit[0]
        vol, info = drt_mart(images[0], cams[0], grid, iterations=iterations, mu=mu, rays_per_pixel=rays_per_pixel,
                             min_coverage=min_coverage, matrix=matrix, progress=progress, return_info=True)
        info["weights_s"] += t_weights  # built here (0 when the cache held them)
        return vol, info
    whites = list(whites) if whites is not None else [None] * len(images)
    if len(whites) != len(images):
        raise ConfigError(f"reconstruct: give one white image per raw image ({len(images)}), got {len(whites)}.")
    vols = [plenoptic_volume(decode(img, optics=c, white=w), grid, method=combine, progress=progress)
            for img, c, w in zip(images, cams, whites, strict=True)]
    return (vols[0] if len(vols) == 1 else fuse(vols, normalise=fuse_normalise)), {"cameras": len(vols)}
