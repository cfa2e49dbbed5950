"""``mitpiv preview``: a picture of a rig before any render.

A scene XML places the cameras and the laser sheet, and an experiment the seeding box and
the measurement volume, but only as numbers: a camera aimed past the volume, or focused
beside the sheet, shows up as a black or blurred image after the render. :func:`preview`
loads a scene's sensors and laser sheets alone (:func:`~mitpiv.studies.shared.load_scene_rig`:
no particle file, no Mie table; about a second) and writes into ``out_dir``

* ``rig.png``: the rig in 3D at equal scale [mm]: each camera's frustum (its pinhole or
  main-lens centre to the chief rays through the four sensor corners, drawn out to its
  working distance, labelled with its id), the laser sheet (a slab of its thickness over its
  mid-plane within the volume, else within the cameras' common view), the seeding box and the
  measurement volume as wireframes, and for a plenoptic camera its main lens (a disc of its
  aperture) and its microlens array's footprint; beside it a close-up of the volume with each
  camera's field of view on the sheet's mid-plane;
* ``views.png``: one panel per camera, its sensor outline (W x H px) with the projected edges
  of the volume and of the seeding box and the footprint of the sheet's slab, on axes that
  reach beyond the sensor so that what falls off it shows; the title gives the share of the
  volume the camera sees and of the sheet's mid-plane it has in focus;
* ``rig.vtu``: the same geometry for ParaView (lines and polygons; cell arrays ``part``
  and ``camera``, named in ``rig.json``), written by :func:`mitpiv.io.vtk.write_cells`;
* ``rig.json``: the numbers (cameras, volume, coverage, focus, warnings).

It warns as ``mitpiv run --check`` does, with the same functions: for an experiment the
kind's own ``scene_check`` / ``rig_check`` of every stage (the volume in every camera's
view, :func:`~mitpiv.studies.shared.check_coverage`; the sheet within each camera's depth of
field, :func:`~mitpiv.studies.shared.check_sheet_focus`); for a scene XML the same two
functions on ``volume_mm`` (without it the focus check covers the cameras' common view of the
sheet). A volume no point of which every camera sees, which ``mitpiv run`` refuses, is a
warning here too, since the preview is there to show it: :func:`preview` writes every file
and reports it as ``"refused"`` (``mitpiv preview`` then exits with status 1).

What is hand-written here, and why: the drawings (Matplotlib has no frustum or slab; a
frustum is the camera's ``pixel_to_ray`` at the sensor corners and a rectangle, the sheet a
prism over :func:`~mitpiv.physics.sheet.plane_box_section`). Projection, visibility,
coverage, depth of field and the checks are the library's own.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from mitpiv.errors import ConfigError, MitpivWarning

__all__ = ["preview", "PARTS"]

#: The ``part`` cell array of ``rig.vtu``: code -> what the cell draws.
PARTS = {1: "volume", 2: "seeding box", 3: "laser sheet", 4: "camera frustum", 5: "main lens", 6: "MLA footprint"}

_SHEET_COLOUR = "tab:green"


def preview(path, out_dir, *, volume_mm=None, params: dict | None = None, overrides: dict | None = None) -> dict:
    """Draw the rig of a scene XML or an experiment TOML into ``out_dir`` (module docstring).

    Parameters
    ----------
    path : path
        A scene XML or an experiment TOML (kinds with a ``[scene]``: tomo, tracking).
    out_dir : path
        Folder for ``rig.png``, ``views.png``, ``rig.vtu`` and ``rig.json`` (created).
    volume_mm : sequence of 6 float, optional
        Scene XML only: the measurement volume ``x0 x1 y0 y1 z0 z1`` [mm] (an experiment
        gives its own: ``[reconstruction] bounds_mm``, or a tracking run's box).
    params : dict, optional
        Scene XML only: ``$name`` substitutions.
    overrides : dict, optional
        Experiment only: dotted-key overrides (``{"scene.params.az0": 40}``).

    Returns
    -------
    dict
        ``"files"`` (paths written), ``"warnings"`` (their texts; also issued as
        :class:`~mitpiv.errors.MitpivWarning`), ``"refused"`` (the message of a check that
        ``mitpiv run`` would refuse on, or None), ``"coverage"`` and ``"focus"`` (as in
        ``rig.json``).
    """
    path, out = Path(path), Path(out_dir)
    if not path.is_file():
        raise ConfigError(f"preview: {str(path)!r} does not exist; give a scene XML or an experiment TOML.")
    suffix = path.suffix.lower()
    if suffix not in (".xml", ".toml"):
        raise ConfigError(f"preview: {str(path)!r} is neither a scene XML (.xml) nor an experiment TOML (.toml).")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        if suffix == ".toml":
            if volume_mm is not None or params:
                raise ConfigError("preview: --volume and -D are for a scene XML; an experiment gives its volume "
                                  "([reconstruction] / [tracking] bounds_mm) and its scene parameters ([scene] "
                                  "params; --set scene.params.NAME=VALUE).")
            setup = _experiment_setup(path, overrides)
        else:
            if overrides:
                raise ConfigError("preview: --set is for an experiment TOML; give a scene XML's parameters as "
                                  "-D NAME=VALUE.")
            setup = _scene_setup(path, params, volume_mm)
    texts = [str(w.message) for w in caught if issubclass(w.category, MitpivWarning)]
    result = _draw(setup, out, texts)
    for w in caught:  # issued again once the files are written: the caller's filters and printing apply
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    return {**result, "warnings": texts, "refused": setup["refused"]}


# ------------------------------------------------------------------------------- set-ups
def _experiment_setup(path: Path, overrides) -> dict:
    from mitpiv.studies.kinds import get_kind
    from mitpiv.studies.runner import load_experiment
    from mitpiv.studies.shared import bounds_of, scene_rig

    cfg = load_experiment(path, overrides)
    if getattr(cfg, "scene", None) is None:
        raise ConfigError(f"preview: experiment {str(path)!r} (kind {cfg.kind!r}) has no [scene] XML; preview draws the "
                          f"rig of a scene (the tomo and tracking kinds).")
    rig = scene_rig(cfg)
    volume, what = None, None
    rec = getattr(cfg, "reconstruction", None)
    if rec is not None and getattr(rec, "bounds_mm", None) is not None:
        b = rec.bounds_mm
        volume, what = (np.array([b[0], b[2], b[4]], float), np.array([b[1], b[3], b[5]], float)), \
            "[reconstruction] bounds_mm"
    elif getattr(cfg, "tracking", None) is not None:
        volume = bounds_of(cfg)
        what = "[tracking] bounds_mm" if cfg.tracking.bounds_mm is not None else "the seeding box"
    seeding = getattr(cfg, "seeding", None)
    box = None
    if seeding is not None and getattr(seeding, "box_min_mm", None) is not None:
        box = (np.asarray(seeding.box_min_mm, float), np.asarray(seeding.box_max_mm, float))
    refused = None
    stages = get_kind(cfg.kind).stages(cfg)  # as mitpiv run --check: the checks that may refuse first
    for check, arg in [(s.scene_check, rig.cameras) for s in stages] + [(s.rig_check, rig) for s in stages]:
        if check is not None:
            try:
                check(cfg, arg)
            except ConfigError as e:
                refused = str(e)
                warnings.warn(f"{e} (mitpiv run refuses this experiment; preview draws it anyway)", MitpivWarning,
                              stacklevel=2)
    return {"name": cfg.name, "source": str(path), "rig": rig, "volume": volume, "volume_what": what,
            "seeding": box, "refused": refused}


def _scene_setup(path: Path, params, volume_mm) -> dict:
    from mitpiv.studies.shared import check_coverage, check_sheet_focus, load_scene_rig

    rig = load_scene_rig(path, params=params, where=f"scene {str(path)!r}")
    volume, refused = None, None
    if volume_mm is not None:
        v = np.asarray(volume_mm, float).ravel()
        if v.shape != (6,) or not np.all(np.isfinite(v)) or np.any(v[1::2] <= v[0::2]):
            raise ConfigError(f"preview: --volume must be six finite numbers X0 X1 Y0 Y1 Z0 Z1 [mm] with X0 < X1, Y0 < "
                              f"Y1, Z0 < Z1, got {v.tolist()}.")
        volume = (v[0::2].copy(), v[1::2].copy())
        try:
            check_coverage(rig.cameras, *volume, what=f"preview of {path.name}: --volume",
                           fix="aim the cameras at the volume, or give --volume within their common view")
        except ConfigError as e:
            refused = str(e)
            warnings.warn(f"{e} (mitpiv run would refuse this volume; preview draws it anyway)", MitpivWarning,
                          stacklevel=2)
    lo, hi = volume if volume is not None else (None, None)
    check_sheet_focus(rig, lo, hi, what=f"preview of {path.name}" +
                      ("" if volume is not None else " (no --volume: within the cameras' common view)"))
    return {"name": path.stem if path.stem != "scene" else path.parent.name, "source": str(path), "rig": rig,
            "volume": volume, "volume_what": "--volume" if volume is not None else None, "seeding": None,
            "refused": refused}


# ------------------------------------------------------------------------------- geometry
def _box_corners(lo, hi) -> np.ndarray:
    from mitpiv.physics.camera import box_corners

    return box_corners(lo, hi)


#: The 12 edges of a box as pairs of :func:`_box_corners` indices.
_EDGES = [(a, a | (1 << i)) for a in range(8) for i in range(3) if not a & (1 << i)]


def _camera_geometry(name, cam, setup, region_centre) -> dict:
    """Frustum (pinhole, far corners), axis, working distance; main lens and MLA of a
    plenoptic camera."""
    from mitpiv.physics.camera import camera_to_world, focal_depth, sensor_corner_rays

    pos, dirs = sensor_corner_rays(cam)
    m = camera_to_world(cam)
    axis = m[:3, 2]
    fd = focal_depth(cam)
    if setup["volume"] is not None:
        target = 0.5 * (setup["volume"][0] + setup["volume"][1])
    else:
        target = region_centre
    wd = float((target - pos) @ axis) if target is not None else -1.0
    if not wd > 0:
        wd = fd["focus_distance_mm"] if fd is not None else 100.0
    far = pos + dirs * (wd / (dirs @ axis))[:, None]
    out = {"id": name, "position_mm": pos, "axis": axis, "working_distance_mm": wd, "far_mm": far,
           "type": "plenoptic" if hasattr(cam, "angular_samples") else "pinhole", "focus": fd,
           "resolution": tuple(int(v) for v in cam.resolution)}
    if out["type"] == "plenoptic":
        ang = np.linspace(0.0, 2.0 * np.pi, 48, endpoint=False)
        r = cam.aperture_radius_mm
        out["lens_mm"] = pos + r * (np.cos(ang)[:, None] * m[:3, 0] + np.sin(ang)[:, None] * m[:3, 1])
        nx, ny = cam.mla_count
        a1, a2 = cam.basis_mm
        o = cam.origin_mm
        xy = np.array([o + i * a1 + j * a2 for i, j in ((-0.5, -0.5), (nx - 0.5, -0.5), (nx - 0.5, ny - 0.5),
                                                         (-0.5, ny - 0.5))])
        local = np.column_stack([xy, np.full(4, -cam.image_distance_mm), np.ones(4)])
        out["mla_mm"] = (local @ m.T)[:, :3]
    return out


def _geometry(setup) -> dict:
    from mitpiv.studies.shared import sheet_region

    rig = setup["rig"]
    lo, hi = setup["volume"] if setup["volume"] is not None else (None, None)
    sheets = {}
    for sid, sheet in rig.sheets.items():
        region = sheet_region(rig, sheet, lo, hi)
        if not len(region) and lo is not None:  # the mid-plane misses the volume: show where it is
            region = sheet_region(rig, sheet)
        if not len(region):
            continue
        half = 0.5 * float(sheet["thickness_mm"]) * np.asarray(sheet["normal"], float)
        sheets[sid] = {"mid_mm": region, "faces_mm": (region - half, region + half), "sheet": sheet}
    centres = [s["mid_mm"].mean(axis=0) for s in sheets.values()]
    centre = centres[0] if centres else None
    cams = {name: _camera_geometry(name, cam, setup, centre) for name, cam in rig.cameras.items()}
    return {"sheets": sheets, "cameras": cams}


# ------------------------------------------------------------------------------- drawing
def _draw(setup, out: Path, texts) -> dict:
    from mitpiv.io import write_json
    from mitpiv.physics.camera import box_coverage
    from mitpiv.studies.shared import sheet_focus

    out.mkdir(parents=True, exist_ok=True)
    rig = setup["rig"]
    geo = _geometry(setup)
    lo, hi = setup["volume"] if setup["volume"] is not None else (None, None)
    cov = box_coverage(rig.cameras, lo, hi) if lo is not None and rig.cameras else None
    focus = sheet_focus(rig, lo, hi)
    files = [_draw_rig(setup, geo, out / "rig.png"), _draw_views(setup, geo, cov, focus, out / "views.png"),
             _write_vtk(setup, geo, out / "rig.vtu")]
    cameras = []
    for k, (name, g) in enumerate(geo["cameras"].items()):
        c = {"index": k, "id": name, "type": g["type"], "resolution": list(g["resolution"]),
             "position_mm": g["position_mm"], "axis": g["axis"], "working_distance_mm": g["working_distance_mm"],
             "focus": g["focus"], "focus_plane_normal_camera_mitsuba": rig.focus_normals.get(name)}
        if cov is not None:
            c["volume_seen"] = cov["cameras"][name]["fraction"]
        for sid, f in focus.items():
            if name in f["cameras"]:
                c.setdefault("sheet_in_focus", {})[sid] = f["cameras"][name]["in_focus"]
        cameras.append(c)
    record = {"source": setup["source"], "name": setup["name"], "cameras": cameras,
              "volume_mm": None if lo is None else [lo, hi], "volume_from": setup["volume_what"],
              "seeding_box_mm": None if setup["seeding"] is None else list(setup["seeding"]),
              "volume_seen_by_all": None if cov is None else cov["common"],
              "sheets": {sid: {**s["sheet"], "region_mm": s["mid_mm"]} for sid, s in geo["sheets"].items()},
              "parts": {str(k): v for k, v in PARTS.items()}, "warnings": texts, "refused": setup["refused"]}
    files.append(write_json(out / "rig.json", _finite(record), default=str))
    return {"files": files, "coverage": cov, "focus": focus}


def _finite(x):
    """A record with each non-finite number (an infinite far limit of focus) as None: strict JSON."""
    from mitpiv.io.records import to_jsonable

    x = to_jsonable(x)
    if isinstance(x, dict):
        return {k: _finite(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_finite(v) for v in x]
    return None if isinstance(x, float) and not np.isfinite(x) else x


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _colour(k: int):
    import matplotlib

    return matplotlib.colormaps["tab10"](k % 10)


def _box_lines(ax, lo, hi, **kw):
    c = _box_corners(lo, hi)
    for a, b in _EDGES:
        ax.plot(*c[[a, b]].T, **kw)
        kw.pop("label", None)


def _poly3d(ax, poly, **kw):
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    ax.add_collection3d(Poly3DCollection([poly], **kw))


def _slab(ax, s, colour, clip=None):
    lo_face, hi_face = s["faces_mm"]
    if clip is not None:
        lo_face, hi_face = _clip_box(lo_face, *clip), _clip_box(hi_face, *clip)
    for face in (lo_face, hi_face):
        if len(face) >= 3:
            _poly3d(ax, face, facecolor=colour, edgecolor=colour, alpha=0.18, linewidths=0.8)
    mid = s["mid_mm"] if clip is None else _clip_box(s["mid_mm"], *clip)
    if len(mid) >= 3:
        ax.plot(*np.vstack([mid, mid[:1]]).T, color=colour, lw=1.0, ls="--")


def _clip_box(poly, lo, hi) -> np.ndarray:
    from mitpiv.physics.sheet import clip_polygon

    for i in range(3):
        e = np.zeros(3)
        e[i] = 1.0
        poly = clip_polygon(poly, hi, e)
        poly = clip_polygon(poly, lo, -e)
    return poly


def _equal_3d(ax, pts):
    pts = np.asarray(pts, float).reshape(-1, 3)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    span = max(float((hi - lo).max()), 1e-6)
    pad = 0.05 * span
    lo, hi = lo - pad, hi + pad
    hi = np.maximum(hi, lo + 0.02 * span)  # a flat rig keeps a sliver of height
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_zlim(lo[2], hi[2])
    ax.set_box_aspect(tuple(hi - lo))  # equal scale on the three axes
    from matplotlib.ticker import MaxNLocator

    for axis, extent in zip((ax.xaxis, ax.yaxis, ax.zaxis), hi - lo, strict=True):  # fewer ticks on a short axis
        axis.set_major_locator(MaxNLocator(nbins=max(2, int(round(7 * extent / (hi - lo).max())))))
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    ax.set_zlabel("z [mm]")


def _draw_rig(setup, geo, path: Path) -> Path:
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    from mitpiv.io.figures import save_figure

    plt = _plt()
    fig = plt.figure(figsize=(15, 7.5), constrained_layout=True)
    ax = fig.add_subplot(1, 2, 1, projection="3d")
    zoom = fig.add_subplot(1, 2, 2, projection="3d")
    vol, seed = setup["volume"], setup["seeding"]
    pts = []
    cams = list(geo["cameras"].values())
    reach = max([float(np.linalg.norm(g["far_mm"] - g["position_mm"], axis=1).max()) for g in cams] + [1.0])
    labels = []  # cameras within 2 % of the rig's reach of one another share a label
    for k, g in enumerate(cams):
        col = _colour(k)
        p, far = g["position_mm"], g["far_mm"]
        for q in far:
            ax.plot(*np.stack([p, q]).T, color=col, lw=0.8)
        ax.plot(*np.vstack([far, far[:1]]).T, color=col, lw=1.2)
        ax.scatter(*p, color=col, s=14)
        same = next((lab for lab in labels if np.linalg.norm(lab[0] - p) < 0.02 * reach), None)
        if same is None:
            labels.append([p, [g["id"]], col])
        else:
            same[1].append(g["id"])
        pts += [p[None], far]
        if "lens_mm" in g:
            _poly3d(ax, g["lens_mm"], facecolor=col, edgecolor="k", alpha=0.5, linewidths=0.5)
            _poly3d(ax, g["mla_mm"], facecolor="none", edgecolor=col, linewidths=1.0)
    for p, names, col in labels:
        ax.text(*p, " " + " / ".join(names), color=col if len(names) == 1 else "k", fontsize=8)
    for target in (ax, zoom):
        if vol is not None:
            _box_lines(target, *vol, color="k", lw=1.3)
        if seed is not None:
            _box_lines(target, *seed, color="0.45", lw=1.0, ls=":")
    for s in geo["sheets"].values():
        _slab(ax, s, _SHEET_COLOUR)
        pts += list(s["faces_mm"])
    for box in (vol, seed):
        if box is not None:
            pts.append(_box_corners(*box))
    _equal_3d(ax, np.concatenate(pts) if pts else np.zeros((1, 3)))
    nc = len(geo["cameras"])
    ax.set_title(f"{setup['name']}: the rig ({nc} camera{'s' if nc != 1 else ''}; frusta drawn to the working "
                 f"distance)", fontsize=10)

    # the close-up: the volume (else the sheet region), the slab and each camera's view on the mid-plane
    near = [b for b in (vol, seed) if b is not None]
    if near:
        lo = np.min([b[0] for b in near], axis=0)
        hi = np.max([b[1] for b in near], axis=0)
    elif geo["sheets"]:
        allp = np.concatenate([s["mid_mm"] for s in geo["sheets"].values()])
        lo, hi = allp.min(axis=0), allp.max(axis=0)
    else:
        lo, hi = -np.ones(3), np.ones(3)
    span = float((hi - lo).max())
    for s in geo["sheets"].values():  # the slab's whole thickness, up to twice the volume's span beyond it
        for face in s["faces_mm"]:
            face = _clip_box(face, lo - 2 * span, hi + 2 * span)
            if len(face):
                lo, hi = np.minimum(lo, face.min(axis=0)), np.maximum(hi, face.max(axis=0))
    span = float((hi - lo).max())
    lo, hi = lo - 0.15 * span, hi + 0.15 * span
    for s in geo["sheets"].values():
        _slab(zoom, s, _SHEET_COLOUR, clip=(lo, hi))
    sheet = next(iter(geo["sheets"].values()), None)
    centre = 0.5 * (lo + hi)
    for k, g in enumerate(geo["cameras"].values()):
        col = _colour(k)
        if sheet is not None:  # the camera's field of view on the sheet's mid-plane
            n = np.asarray(sheet["sheet"]["normal"], float)
            o = np.asarray(sheet["sheet"]["origin_mm"], float)
            d = g["far_mm"] - g["position_mm"]
            with np.errstate(divide="ignore", invalid="ignore"):
                t = ((o - g["position_mm"]) @ n) / (d @ n)
            if np.all(np.isfinite(t) & (t > 0)):
                fp = _clip_box(g["position_mm"] + t[:, None] * d, lo, hi)
                if len(fp) >= 3:
                    zoom.plot(*np.vstack([fp, fp[:1]]).T, color=col, lw=1.4)
        to_cam = g["position_mm"] - centre
        tip = centre + 0.45 * span * to_cam / np.linalg.norm(to_cam)
        zoom.plot(*np.stack([centre, tip]).T, color=col, lw=1.0, ls="-.")
        if len(geo["cameras"]) <= 8:  # more labels would hide one another
            zoom.text(*tip, f" {g['id']}", color=col, fontsize=8)
    _equal_3d(zoom, np.stack([lo, hi]))
    zoom.set_title("around the volume: each camera's view on the sheet mid-plane (solid)\nand its direction "
                   "(dash-dot)", fontsize=10)
    handles = [Line2D([], [], color="k", lw=1.3, label=f"measurement volume ({setup['volume_what']})")] \
        if vol is not None else []
    if seed is not None:
        handles.append(Line2D([], [], color="0.45", ls=":", label="seeding box"))
    if geo["sheets"]:
        t = ", ".join(f"{s['sheet']['thickness_mm']:g}" for s in geo["sheets"].values())
        handles.append(Patch(facecolor=_SHEET_COLOUR, alpha=0.3, label=f"laser sheet ({t} mm thick; dashed: "
                                                                            f"mid-plane)"))
    handles += [Line2D([], [], color=_colour(k), label=g["id"] + (" (plenoptic: main lens, MLA)"
                                                                  if g["type"] == "plenoptic" else ""))
                for k, g in enumerate(geo["cameras"].values())][:12]
    fig.legend(handles=handles, loc="outside lower center", ncol=min(len(handles), 5), fontsize=8, frameon=False)
    save_figure(fig, path, dpi=90)
    return path


def _project(cam, pts):
    """Pixel positions of points (..., 3), NaN behind the camera."""
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        uv = np.asarray(cam.project(pts), float)
        front = np.asarray(cam.in_front(pts), bool)
    uv[~front] = np.nan
    return uv


def _edge_points(lo, hi, n: int = 33) -> np.ndarray:
    """(12, n, 3) points along a box's edges (curved in a distorted view)."""
    c = _box_corners(lo, hi)
    t = np.linspace(0.0, 1.0, n)[:, None]
    return np.stack([c[a] + t * (c[b] - c[a]) for a, b in _EDGES])


def _draw_views(setup, geo, cov, focus, path: Path) -> Path:
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch, Polygon, Rectangle
    from scipy.spatial import ConvexHull, QhullError

    from mitpiv.io.figures import save_figure

    plt = _plt()
    rig = setup["rig"]
    n = max(len(rig.cameras), 1)
    ncol = min(n, 4)
    nrow = -(-n // ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(max(4.4 * ncol, 8.0), 3.9 * nrow + 0.8), constrained_layout=True,
                             squeeze=False)
    vol, seed = setup["volume"], setup["seeding"]
    for ax in axes.ravel()[len(rig.cameras):]:
        ax.axis("off")
    for ax, (name, cam) in zip(axes.ravel(), rig.cameras.items(), strict=False):
        w, h = cam.resolution
        seen = [np.array([[0.0, 0.0], [w, h]])]
        for s in geo["sheets"].values():
            prism = np.concatenate(s["faces_mm"])
            uv = _project(cam, prism)
            uv = uv[np.all(np.isfinite(uv), axis=1)]
            if len(uv) >= 3:
                try:
                    hull = uv[ConvexHull(uv).vertices]
                except QhullError:
                    continue
                ax.add_patch(Polygon(hull, closed=True, facecolor=_SHEET_COLOUR, alpha=0.2, edgecolor=_SHEET_COLOUR))
                seen.append(hull)
        for box, style in ((seed, dict(color="0.45", lw=1.0, ls=":")), (vol, dict(color="tab:blue", lw=1.3))):
            if box is None:
                continue
            for edge in _project(cam, _edge_points(*box)):
                ax.plot(edge[:, 0], edge[:, 1], **style)
                seen.append(edge[np.all(np.isfinite(edge), axis=1)])
        ax.add_patch(Rectangle((0, 0), w, h, fill=False, edgecolor="k", lw=2.0, zorder=5))
        pts = np.concatenate([p for p in seen if len(p)])
        u0, u1 = max(pts[:, 0].min(), -2.0 * w), min(pts[:, 0].max(), 3.0 * w)
        v0, v1 = max(pts[:, 1].min(), -2.0 * h), min(pts[:, 1].max(), 3.0 * h)
        pu, pv = 0.04 * (u1 - u0), 0.04 * (v1 - v0)
        ax.set_xlim(u0 - pu, u1 + pu)
        ax.set_ylim(v1 + pv, v0 - pv)  # image rows run down
        ax.set_aspect("equal")
        ax.set_xlabel("u [px]")
        ax.set_ylabel("v [px]")
        title = f"{name} ({w} x {h} px)"
        if cov is not None:
            title += f": sees {100 * cov['cameras'][name]['fraction']:.0f} % of the volume"
        infocus = [f["cameras"][name]["in_focus"] for f in focus.values() if name in f["cameras"]]
        if infocus:
            title += f"\nsheet mid-plane {100 * min(infocus):.0f} % in focus"
        elif geo["sheets"] and geo["cameras"][name]["focus"] is None:
            title += "\nideal pinhole: in focus at every depth"
        ax.set_title(title, fontsize=9, color="k" if cov is None or cov["cameras"][name]["fraction"] >= 0.9
                     else "tab:red")
        ax.tick_params(labelsize=7)
    handles = [Line2D([], [], color="k", lw=2.0, label="sensor outline")]
    if vol is not None:
        handles.append(Line2D([], [], color="tab:blue", lw=1.3, label=f"measurement volume ({setup['volume_what']})"))
    if seed is not None:
        handles.append(Line2D([], [], color="0.45", ls=":", label="seeding box"))
    if geo["sheets"]:
        handles.append(Patch(facecolor=_SHEET_COLOUR, alpha=0.3, label="laser sheet slab"))
    fig.legend(handles=handles, loc="outside lower center", ncol=min(len(handles), 2 if ncol == 1 else 4), fontsize=8,
               frameon=False)
    fig.suptitle(f"{setup['name']}: what each camera sees (axes reach beyond the sensor)", fontsize=10)
    save_figure(fig, path, dpi=90)
    return path


def _write_vtk(setup, geo, path: Path) -> Path:
    from mitpiv.io.vtk import write_cells

    points, cells, part, camera = [], [], [], []

    def add(pts, cell_list, code, cam=-1):
        base = sum(len(p) for p in points)
        points.append(np.asarray(pts, float).reshape(-1, 3))
        for c in cell_list:
            cells.append([base + i for i in c])
            part.append(code)
            camera.append(cam)

    loops = [(a, b) for a, b in _EDGES]
    for box, code in ((setup["volume"], 1), (setup["seeding"], 2)):
        if box is not None:
            add(_box_corners(*box), loops, code)
    for s in geo["sheets"].values():
        a, b = s["faces_mm"]
        k = len(a)
        sides = [[i, (i + 1) % k, k + (i + 1) % k, k + i] for i in range(k)]
        add(np.concatenate([a, b]), [list(range(k)), list(range(k, 2 * k)), *sides], 3)
    for idx, g in enumerate(geo["cameras"].values()):
        add(np.vstack([g["position_mm"][None], g["far_mm"]]),
            [(0, 1), (0, 2), (0, 3), (0, 4), (1, 2), (2, 3), (3, 4), (4, 1)], 4, idx)
        if "lens_mm" in g:
            add(g["lens_mm"], [list(range(len(g["lens_mm"])))], 5, idx)
            add(g["mla_mm"], [[0, 1, 2, 3]], 6, idx)
    pts = np.concatenate(points) if points else np.zeros((1, 3))
    return write_cells(path, pts, cells, {"part": np.asarray(part, np.int32), "camera": np.asarray(camera, np.int32)})
