"""Reports of experiment runs: every figure and every Markdown table of a run is made here,
from the results of its stages and the files they wrote; stages never plot.

:func:`tomo_report` and :func:`backlit_report` return a :class:`Report` (Markdown and a
figure writer per PNG file name); :func:`write` writes it into a folder, each file
atomically.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["Report", "write", "tomo_report", "backlit_report", "tracking_report", "accuracy_report", "save_figure",
           "plot_sweep"]


@dataclass
class Report:
    """Markdown text and the figures it links: ``figures[name](path)`` writes the PNG ``name``."""

    markdown: str
    figures: dict[str, Callable[[Path], None]] = field(default_factory=dict)


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig, path, *, dpi: int = 90) -> None:
    """Save a matplotlib figure atomically and close it (:func:`mitpiv.io.save_figure`)."""
    from mitpiv.io.figures import save_figure as save

    save(fig, path, dpi=dpi)


def write(report: Report, out_dir, *, name: str = "report.md") -> dict:
    """Write the Markdown (``name``) and every figure of ``report`` into ``out_dir``."""
    from mitpiv.io.records import write_text

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    for figure, draw in report.figures.items():
        draw(out / figure)
    write_text(out / name, report.markdown)
    return {"report": name, "figures": list(report.figures)}


def _timings_table(timings: dict) -> list[str]:
    return ["| stage | seconds |", "|---|---|", *[f"| {k} | {v:.1f} |" for k, v in timings.items()]]


# ----------------------------------------------------------------------------- tomo
def _top(img, q: float) -> float | None:
    """The colour-scale maximum: the q-th percentile (a few bright pixels would hide the rest)."""
    return float(np.percentile(img, q)) or None


def _colorbar(fig, im, label: str, **kw):
    """A colour bar whose ticks read without an offset: values of a scale far from 1 (an
    image's 1e-6 W sr^-1 mm^-2) are ticked in units of its power of ten, which the label
    names (``radiance [1e-06 W sr^-1 mm^-2]``)."""
    import re

    from matplotlib.ticker import FuncFormatter

    cb = fig.colorbar(im, **kw)
    top = max(abs(float(im.norm.vmin or 0.0)), abs(float(im.norm.vmax or 0.0)))
    if top > 0 and not 1e-2 <= top < 1e4:
        e = int(np.floor(np.log10(top)))
        cb.formatter = FuncFormatter(lambda v, _pos: f"{v / 10.0 ** e:g}")
        cb.update_ticks()
        label = re.sub(r"\[", f"[1e{e:+03d} ", label, count=1) if "[" in label else f"{label} [1e{e:+03d}]"
    cb.set_label(label, fontsize=8)
    cb.ax.tick_params(labelsize=7)
    return cb


def intensity_unit(meta: dict | None) -> str:
    """The unit of an image's pixel values, short, from its metadata: ``counts`` after a
    sensor model (a ``sensor`` record), else the render's ``units.pixel_value`` up to its
    bracketed unit (``radiance [W sr^-1 mm^-2]``); ``image units`` where none is stated."""
    import re

    meta = meta or {}
    if meta.get("sensor"):
        return "counts"
    text = str((meta.get("units") or {}).get("pixel_value") or "")
    m = re.match(r"[^\[;,]*\[[^\]]*\]", text)
    return (m.group(0) if m else text.split(";")[0].split(",")[0]).strip() or "image units"


def _sensor_images(imgs, files, metas=None):
    """One row of the cameras' images of a frame (grey scale to each image's 99.9th
    percentile, the rest saturates), each with its colour bar in the image's unit."""
    metas = metas or [None] * len(imgs)

    def draw(path):
        plt = _plt()
        n = len(imgs)
        fig, axs = plt.subplots(1, n, figsize=(3.3 * n, 3.9), squeeze=False)
        for ax, img, f, meta in zip(axs[0], imgs, files, metas, strict=True):
            im = ax.imshow(img, cmap="gray", vmin=0, vmax=_top(img, 99.9), interpolation="antialiased")
            h, w = img.shape[:2]
            ax.set_title(f"{Path(f).stem} ({w} x {h} px)", fontsize=9)
            ax.axis("off")
            _colorbar(fig, im, intensity_unit(meta), ax=ax, orientation="horizontal", fraction=0.05, pad=0.03,
                      extend="max")
        fig.suptitle("camera images (colour scale to each image's 99.9th percentile)", fontsize=10)
        fig.tight_layout(rect=(0, 0, 1, 0.95))
        save_figure(fig, path)

    return draw


def _volume_projections(vol, grid, frame: int = 0):
    """Maximum-intensity projections of a volume along z (x-y), y (x-z) and x (z-y), laid out
    as orthogonal views on mm axes at equal scale, one colour scale (to the 99.5th
    percentile of the projections)."""
    def draw(path):
        plt = _plt()
        ex, ey, ez = _extent(grid.x_mm), _extent(grid.y_mm), _extent(grid.z_mm)
        wx, wy, wz = (e[1] - e[0] for e in (ex, ey, ez))
        pz, py, px = vol.max(axis=0), vol.max(axis=1), vol.max(axis=2)  # (ny, nx), (nz, nx), (nz, ny)
        vmax = _top(np.concatenate([pz.ravel(), py.ravel(), px.ravel()]), 99.5)
        gap, left, right, bottom, top = 0.75, 0.75, 1.25, 0.6, 0.55  # inches
        s = min(7.0 / (wx + wz), 6.5 / (wy + wz))  # inches per mm
        side = max(s * wz, 0.45)  # a thin volume's side views stay visible
        fw, fh = left + s * wx + gap + side + right, bottom + side + gap + s * wy + top
        fig = plt.figure(figsize=(fw, fh))

        def axes(x0, y0, w, h):
            return fig.add_axes((x0 / fw, y0 / fh, w / fw, h / fh))

        a_xy = axes(left, bottom + side + gap, s * wx, s * wy)
        a_xz = axes(left, bottom, s * wx, side)
        a_zy = axes(left + s * wx + gap, bottom + side + gap, side, s * wy)
        kw = {"cmap": "magma", "origin": "lower", "vmin": 0, "vmax": vmax, "interpolation": "antialiased"}
        im = a_xy.imshow(pz, extent=(*ex, *ey), **kw)
        a_xz.imshow(py, extent=(*ex, *ez), **kw)
        a_zy.imshow(px.T, extent=(*ez, *ey), **kw)
        for ax, (h, v) in ((a_xy, "xy"), (a_xz, "xz"), (a_zy, "zy")):
            ax.set_aspect("equal" if s * wz >= 0.45 or "z" not in h + v else "auto")
            ax.set_xlabel(f"{h} [mm]", fontsize=9)
            ax.set_ylabel(f"{v} [mm]", fontsize=9)
            ax.tick_params(labelsize=8)
        a_xy.set_title(f"frame {frame} volume, maximum along z", fontsize=9)
        a_xz.set_title("maximum along y", fontsize=9)
        a_zy.set_title("maximum along x", fontsize=9)
        cax = axes(left + s * wx + gap + side + 0.15, bottom + side + gap, 0.14, s * wy)
        _colorbar(fig, im, "reconstructed intensity [a.u.]", cax=cax, extend="max")
        save_figure(fig, path)

    return draw


def _volume_slices(vol, grid, frame: int = 0, n: int = 5, zoom_mm: float = 6.0):
    """``n`` z slices of a volume on mm axes, one colour scale: 0 to the 99.9th percentile of
    the volume's positive voxels (a particle's peak is far above: the scale to the maximum
    shows black slices); below each, its central ``zoom_mm`` square at full resolution,
    where single particles show."""
    def draw(path):
        plt = _plt()
        from matplotlib.patches import Rectangle

        ks = np.linspace(0, vol.shape[0] - 1, n).round().astype(int)
        pos = vol[vol > 0]
        vmax = float(np.percentile(pos, 99.9)) if pos.size else None
        ex, ey = _extent(grid.x_mm), _extent(grid.y_mm)
        r = (ey[1] - ey[0]) / (ex[1] - ex[0])
        cx, cy = 0.5 * (ex[0] + ex[1]), 0.5 * (ey[0] + ey[1])
        hz = 0.5 * min(zoom_mm, ex[1] - ex[0], ey[1] - ey[0])
        fig, axs = plt.subplots(2, n, figsize=(2.9 * n + 1.0, 2.9 * r + 2.9 + 0.9), squeeze=False,
                                gridspec_kw={"height_ratios": (r, 1.0)})
        kw = {"cmap": "magma", "origin": "lower", "vmin": 0, "vmax": vmax, "extent": (*ex, *ey)}
        for c, k in enumerate(ks):
            a, b = axs[0, c], axs[1, c]
            im = a.imshow(vol[k], interpolation="antialiased", **kw)
            a.set_title(f"z = {grid.z_mm[k]:+.2f} mm", fontsize=9)
            a.add_patch(Rectangle((cx - hz, cy - hz), 2 * hz, 2 * hz, fill=False, ec="c", lw=0.8))
            b.imshow(vol[k], interpolation="nearest", **kw)
            b.set_xlim(cx - hz, cx + hz)
            b.set_ylim(cy - hz, cy + hz)
            for ax in (a, b):
                ax.set_aspect("equal")
                ax.tick_params(labelsize=7)
                ax.set_xlabel("x [mm]", fontsize=8)
                if c == 0:
                    ax.set_ylabel("y [mm]", fontsize=8)
                else:
                    ax.tick_params(labelleft=False)
        fig.suptitle(f"frame {frame} volume, z slices (top) and their central {2 * hz:g} mm square (below, cyan box); "
                     "one colour scale to the 99.9th percentile of the positive voxels", fontsize=10)
        fig.tight_layout(rect=(0, 0, 0.93, 1))
        cax = fig.add_axes((0.945, 0.12, 0.012, 0.72))
        _colorbar(fig, im, "reconstructed intensity [a.u.]", cax=cax, extend="max")
        save_figure(fig, path)

    return draw


def _mosaic(raw_file):
    def draw(path):
        from mitpiv.lightfield import decode

        plt = _plt()
        lf = decode(raw_file)
        nv, nu, nt, ns = lf.data.shape
        mosaic = lf.mosaic()
        fig, ax = plt.subplots(figsize=(7, 7 * nv * nt / max(nu * ns, 1)))
        ax.imshow(mosaic, cmap="gray", vmax=float(np.percentile(mosaic, 99.9)) or None)
        ax.set_title(f"{Path(raw_file).stem}: sub-aperture images ({nu} x {nv} views)", fontsize=9)
        ax.axis("off")
        fig.tight_layout()
        save_figure(fig, path)

    return draw


def _particle_errors(run: Path, frame: int):
    def draw(path):
        from mitpiv.analysis import MatchResult

        MatchResult.load(run / "evaluate" / f"matches_{frame}.npz").plot(path, title=f"frame {frame} particle position "
                                                                                 "error")

    return draw


def _velocity_error(run: Path):
    def draw(path):
        from mitpiv.analysis import VectorField, plot_velocity_error
        from mitpiv.io.vectors import read_velocity_error

        plot_velocity_error(VectorField.load(run / "piv" / "field.npz"),
                            read_velocity_error(run / "piv" / "velocity_error.npz"), path)

    return draw


# ------------------------------------------------------------------------- flow figures
def _extent(c):
    """imshow extent of cell-centred samples at coordinates ``c`` (one sample: +-0.5)."""
    c = np.asarray(c, dtype=float)
    h = 0.5 * (c[1] - c[0]) if c.size > 1 else 0.5
    return c[0] - h, c[-1] + h


def _flow_data(run: Path):
    from mitpiv.analysis import VectorField, curl
    from mitpiv.io.vectors import read_velocity_error

    field = VectorField.load(run / "piv" / "field.npz")
    err = read_velocity_error(run / "piv" / "velocity_error.npz")
    meas = np.stack([field.u, field.v, field.w], axis=-1)
    ref = np.asarray(err["reference"], dtype=float)
    return field, meas, ref, np.asarray(err["error"], dtype=float), curl(meas, field.x_mm, field.y_mm, field.z_mm), \
        curl(ref, field.x_mm, field.y_mm, field.z_mm)


#: The principal planes of a field (n_z, n_y, n_x, 3) by their normal: (array axis, in-plane
#: components (horizontal, vertical), normal component, its sign: (h, v, sign n) right-handed).
PLANES = {"z": (0, (0, 1), 2, 1.0), "y": (1, (0, 2), 1, -1.0), "x": (2, (1, 2), 0, 1.0)}


def flow_slice_plane(field, reference, axis: str = "auto", position_mm: float | None = None) -> dict:
    """The plane flow_slice.png draws (``[report] slice_axis`` and ``slice_mm``).

    ``axis`` ``"x"``, ``"y"`` or ``"z"``: the plane of the PIV field normal to it nearest
    ``position_mm`` (default the middle one). ``"auto"``: of the three mid-planes the one
    with the most in-plane motion of ``reference`` (the true window-averaged field,
    (n_z, n_y, n_x, 3)): the largest mean |vorticity| normal to the plane (the in-plane
    rotation the figure colours), or, for a flow without vorticity (its largest mean
    vorticity times the field's size under 5 % of its largest mean in-plane speed), the
    largest mean in-plane speed; ties go to z, then y. (The mean in-plane speed alone
    picks the tomo4 vortex ring's x mid-plane: 45 mm/s of jet through the ring, no core in
    it; the z mid-plane cuts both cores, mean |vorticity| 2.6 1/s against 0.3 1/s.)

    Returns ``{"axis", "index", "position_mm", "by", "mean_in_plane", "mean_vorticity"}``:
    ``by`` the quantity ``"auto"`` ranked by (``"vorticity"`` or ``"speed"``; None for a
    given axis), the last two ``{axis: value on its mid-plane}`` (field unit, and per mm).
    """
    from mitpiv.analysis import curl

    ref = np.asarray(reference, dtype=float)
    coords = {"x": np.asarray(field.x_mm, float), "y": np.asarray(field.y_mm, float), "z": np.asarray(field.z_mm, float)}
    om = curl(ref, coords["x"], coords["y"], coords["z"])
    speeds, vort = {}, {}
    for a, (ax, (h, v), n, _) in PLANES.items():
        mid = ref.shape[ax] // 2
        sl, w = np.take(ref, mid, axis=ax), np.abs(np.take(om, mid, axis=ax)[..., n])
        sp = np.hypot(sl[..., h], sl[..., v])
        speeds[a] = float(np.nanmean(sp)) if np.isfinite(sp).any() else 0.0
        vort[a] = float(np.nanmean(w)) if np.isfinite(w).any() else 0.0
    by = None
    if axis == "auto":
        size = max(float(np.ptp(c)) if c.size > 1 else 0.0 for c in coords.values()) or 1.0
        by = "vorticity" if max(vort.values()) * size > 0.05 * max(speeds.values()) else "speed"
        score = vort if by == "vorticity" else speeds
        axis = max(score, key=lambda a: score[a])  # the first of equals: z, y, x
        index = ref.shape[PLANES[axis][0]] // 2
    else:
        c = coords[axis]
        index = c.size // 2 if position_mm is None else int(np.argmin(np.abs(c - float(position_mm))))
    return {"axis": axis, "index": index, "position_mm": float(coords[axis][index]), "by": by,
            "mean_in_plane": speeds, "mean_vorticity": vort}


def _nice_below(x: float) -> float:
    """The largest of 1, 2, 5 x 10^n not above ``x`` (> 0): a quiver key's length."""
    if not (x > 0 and np.isfinite(x)):
        return 1.0
    e = 10.0 ** np.floor(np.log10(x))
    return float(max(m * e for m in (1, 2, 5) if m * e <= x * (1 + 1e-12)))


def _flow_slice(run: Path, plane: dict, how: str):
    """A plane of the PIV field (``plane``: :func:`flow_slice_plane`): measured and true
    in-plane vectors (one scale, with a reference arrow) over the vorticity normal to the
    plane (or the in-plane speed, where the true flow has no vorticity there), and the
    error magnitude (3D), on mm axes at equal scale. ``how`` says why this plane."""
    def draw(path):
        plt = _plt()
        field, meas, ref, err, om, om_t = _flow_data(run)
        a = plane["axis"]
        ax_i, (h, v), n, sign = PLANES[a]
        k = plane["index"]

        def cut(arr):
            return np.take(arr, k, axis=ax_i)

        coords = {"x": field.x_mm, "y": field.y_mm, "z": field.z_mm}
        hn, vn = "xyz"[h], "xyz"[v]
        ch, cv, unit = np.asarray(coords[hn], float), np.asarray(coords[vn], float), field.units
        ext = (*_extent(ch), *_extent(cv))
        m_s, r_s, e_s = cut(meas), cut(ref), cut(err)
        speed_t = np.hypot(r_s[..., h], r_s[..., v])
        top = float(np.nanmax(speed_t)) if np.isfinite(speed_t).any() else 0.0
        size = max(np.ptp(ch), np.ptp(cv), 1e-9)
        w_t, w_m = sign * cut(om_t)[..., n], sign * cut(om)[..., n]
        lim = float(np.nanmax(np.abs(w_t))) if np.isfinite(w_t).any() else 0.0
        comp = f"({'uvw'[h]}, {'uvw'[v]})"
        if lim > 0.05 * top / size:
            bg = (w_m, w_t)
            kw = {"cmap": "RdBu_r", "vmin": -lim, "vmax": lim}
            sym = f"{'-' if sign < 0 else ''}\\omega_{'xyz'[n]}"
            per = "1/s" if unit == "mm/s" else "1/frame"
            label = f"vorticity ${sym}$ [{per}] (counter-clockwise +)"
        else:
            bg = (np.hypot(m_s[..., h], m_s[..., v]), speed_t)
            kw = {"cmap": "viridis", "vmin": 0.0, "vmax": top or None}
            label = f"in-plane speed |{comp}| [{unit}]"
        r = (ext[3] - ext[2]) / (ext[1] - ext[0])
        stacked = r < 0.45  # a flat plane: three panels one above the other
        spacing = (ch[1] - ch[0]) if ch.size > 1 else size
        step = max(1, int(np.ceil(max(ch.size, cv.size) / (30 if stacked else 20))))
        vv, hh = np.meshgrid(cv[::step], ch[::step], indexing="ij")
        scale = top or 1.0
        arrow = 1.2 * step * spacing  # the longest arrow spans ~1.2 arrow spacings
        # fixed axes in inches (constrained layout would double the drawing time)
        if stacked:
            pw = 9.0
            ph = max(pw * r, 0.9)
            fw, fh = 0.8 + pw + 1.6, 0.45 + 3 * (ph + 0.85) + 0.45
            boxes = [(0.8, 0.45 + (2 - i) * (ph + 0.85) + 0.45, pw, ph) for i in range(3)]
            cboxes = [(0.8 + pw + 0.15, boxes[1][1], 0.13, boxes[0][1] + ph - boxes[1][1]),
                      (0.8 + pw + 0.15, boxes[2][1], 0.13, ph)]
        else:
            pw = 4.2 if r <= 1 else 4.2 / r
            ph = pw * r
            x1 = 0.75 + pw + 0.2
            x3 = x1 + pw + 0.15 + 0.13 + 1.35
            fw, fh = x3 + pw + 0.15 + 0.13 + 0.95, 0.6 + ph + 0.85
            boxes = [(0.75, 0.6, pw, ph), (x1, 0.6, pw, ph), (x3, 0.6, pw, ph)]
            cboxes = [(x1 + pw + 0.15, 0.6, 0.13, ph), (x3 + pw + 0.15, 0.6, 0.13, ph)]
        fig = plt.figure(figsize=(fw, fh))
        axs = [fig.add_axes((x / fw, y / fh, w / fw, hgt / fh)) for x, y, w, hgt in boxes]
        cax = [fig.add_axes((x / fw, y / fh, w / fw, hgt / fh)) for x, y, w, hgt in cboxes]
        where = f"{a} = {plane['position_mm']:+.2f} mm"
        q = None
        for ax, b, vec, title in ((axs[0], bg[0], m_s, "measured"), (axs[1], bg[1], r_s, "true (window average)")):
            im = ax.imshow(b, origin="lower", extent=ext, interpolation="nearest", **kw)
            s = vec[::step, ::step]
            q = ax.quiver(hh, vv, s[..., h], s[..., v], angles="xy", scale_units="xy", scale=scale / arrow,
                          width=0.004 if not stacked else 0.0015, color="k")
            ax.set_title(f"{title}, {where}", fontsize=10)
        key = _nice_below(top) if top > 0 else 1.0
        # the reference arrow below the true panel's lower right corner, right of its axis
        # label (kx: the arrow's tip, labelpos "E"; its label, ~0.9 in, to its right)
        key_in = key * arrow / scale * boxes[1][2] / (ext[1] - ext[0])  # the arrow's length [in]
        kx = max(boxes[1][0] + 0.5 * boxes[1][2] + 0.45 + key_in, boxes[1][0] + boxes[1][2] - 0.9)
        ky = boxes[1][1] - 0.42
        axs[1].quiverkey(q, kx / fw, ky / fh, key, f"{key:g} {unit}", labelpos="E", coordinates="figure",
                         fontproperties={"size": 9})
        fig.colorbar(im, cax=cax[0], label=label)
        e = np.linalg.norm(e_s, axis=-1)
        im = axs[2].imshow(e, origin="lower", extent=ext, cmap="magma", interpolation="nearest",
                           vmin=0, vmax=float(np.nanpercentile(e, 99)) if np.isfinite(e).any() else None)
        out = cut(field.outlier)
        if out.any():
            vo, ho = np.meshgrid(cv, ch, indexing="ij")
            axs[2].plot(ho[out], vo[out], "o", mfc="none", mec="c", ms=7, label="outlier")
            axs[2].legend(fontsize=8, loc="upper right")
        axs[2].set_title(f"|measured - true| (3D), {where}", fontsize=10)
        fig.colorbar(im, cax=cax[1], label=f"error magnitude [{unit}]")
        for i, ax in enumerate(axs):
            ax.set_aspect("equal")
            ax.set_xlabel(f"{hn} [mm]")
            if stacked or i != 1:
                ax.set_ylabel(f"{vn} [mm]")
            else:
                ax.tick_params(labelleft=False)
        fig.suptitle(f"3D PIV on the plane {where} ({how}): in-plane vectors {comp} of measured and true flow at "
                     "one arrow scale", fontsize=10)
        save_figure(fig, path, dpi=100)

    return draw


def _velocity_profiles(run: Path):
    """u, v, w along the x line through the middle of the PIV field: measured (markers,
    outliers ringed), true averaged over each window and true at the point (the flow at
    mid-interval), so the spatial filtering of the windows shows."""
    def draw(path):
        from mitpiv.io import read_truth
        from mitpiv.physics.flows import flow_from_dict

        plt = _plt()
        field, meas, ref, _, _, _ = _flow_data(run)
        k, j = field.shape[0] // 2, field.shape[1] // 2
        x = field.x_mm
        truth = read_truth(run / "particles" / "truth.npz")
        t0, t1 = (float(t) for t in truth["times_s"][:2])
        xf = np.linspace(x[0], x[-1], 200)
        line = np.column_stack([xf, np.full_like(xf, field.y_mm[j]), np.full_like(xf, field.z_mm[k])])
        point = flow_from_dict(dict(truth["flow"]))(line, 0.5 * (t0 + t1))
        if field.dt_s is None:
            point = point * (t1 - t0)
        fig, axs = plt.subplots(1, 3, figsize=(13, 3.8))
        fig.subplots_adjust(left=0.06, right=0.99, bottom=0.15, top=0.88, wspace=0.3)
        out = field.outlier[k, j]
        for c, ax in enumerate(axs):
            ax.plot(xf, point[:, c], "-", color="0.6", lw=1.2, label="true at the point")
            ax.plot(x, ref[k, j, :, c], "k--", lw=1, label="true, window average")
            ax.plot(x, meas[k, j, :, c], "o", color="C0", ms=5, label="measured")
            if out.any():
                ax.plot(x[out], meas[k, j, out, c], "o", mfc="none", mec="r", ms=10, label="outlier")
            ax.set_xlabel("x [mm]")
            ax.set_ylabel(f"{'uvw'[c]} [{field.units}]")
            ax.grid(True, alpha=0.3)
        axs[0].legend(fontsize=8)
        fig.suptitle(f"velocity along x at y = {field.y_mm[j]:+.2f} mm, z = {field.z_mm[k]:+.2f} mm "
                     f"(window {field.window_vox[0]}x{field.window_vox[1]}x{field.window_vox[2]} voxels)", fontsize=10)
        save_figure(fig, path, dpi=100)

    return draw


#: Most particles drawn in a 3D scatter (every k-th beyond it): more hide one another.
MAX_3D_POINTS = 3000


def _particles_3d(run: Path, cfg, frame: int = 0):
    """Detected particles in 3D coloured by their position error, ghosts and missed true
    particles marked; beside it the x-z side view (the depth axis), same colours."""
    def draw(path):
        from mitpiv.analysis import MatchResult
        from mitpiv.io import read_truth
        from mitpiv.studies.export import found_positions, particle_errors

        plt = _plt()
        m = MatchResult.load(run / "evaluate" / f"matches_{frame}.npz")
        truth = read_truth(run / "particles" / "truth.npz")["positions_mm"][frame]
        found = found_positions(run, {"particles": cfg.particles.model_dump()}, frame, m)
        pe = particle_errors(found, truth, m)
        vox = float(max(m.voxel_mm)) if m.voxel_mm is not None else 1.0
        unit = f"voxels of {vox:g} mm" if m.voxel_mm is not None else "mm"
        err = np.linalg.norm(pe["found_error_mm"], axis=1) / vox
        ok, ghost = pe["found_match"], ~pe["found_match"]
        missed = ~pe["true_match"]
        if m.truth_index is not None:  # true particles outside the reconstructed volume are not "missed"
            inside = np.zeros(len(truth), bool)
            inside[m.truth_index] = True
            missed &= inside

        def thin(idx):
            idx = np.flatnonzero(idx)
            return idx[:: max(1, int(np.ceil(idx.size / MAX_3D_POINTS)))]

        fig = plt.figure(figsize=(13, 5.4))
        a3 = fig.add_axes((0.0, 0.04, 0.5, 0.88), projection="3d")
        a2 = fig.add_axes((0.56, 0.11, 0.33, 0.78))
        cax = fig.add_axes((0.915, 0.15, 0.013, 0.7))
        vmax = float(np.percentile(err[ok], 99)) if ok.any() else 1.0
        for ax, dims in ((a3, (0, 1, 2)), (a2, (0, 2))):
            i = thin(missed)
            ax.scatter(*truth[i][:, dims].T, s=3, c="0.75", label=f"missed true ({missed.sum()})")
            i = thin(ok)
            sc = ax.scatter(*found[i][:, dims].T, s=6, c=err[i], cmap="viridis", vmin=0, vmax=vmax,
                            label=f"found, matched ({ok.sum()})")
            i = thin(ghost)
            ax.scatter(*found[i][:, dims].T, s=14, c="r", marker="x", lw=0.8, label=f"ghost ({ghost.sum()})")
        a3.set_xlabel("x [mm]")
        a3.set_ylabel("y [mm]")
        a3.set_zlabel("z [mm]")
        a3.set_box_aspect(np.ptp(np.vstack([truth, found]), axis=0) + 1e-9)
        from matplotlib.ticker import MaxNLocator

        a3.zaxis.set_major_locator(MaxNLocator(3))  # a thin volume's short z axis: few labels
        a3.view_init(elev=22, azim=-60)
        a3.legend(fontsize=8, loc="upper left")
        a2.set_xlabel("x [mm]")
        a2.set_ylabel("z [mm] (depth)")
        a2.set_title("side view (x-z)", fontsize=10)
        fig.colorbar(sc, cax=cax, label=f"|found - true| [{unit}]")
        every = int(np.ceil(ok.sum() / MAX_3D_POINTS))
        fig.suptitle(f"frame {frame}: detected vs true particles, coloured by position error"
                     f"{f' (one in {every} drawn)' if every > 1 else ''}", fontsize=10)
        save_figure(fig, path, dpi=100)

    return draw


def _num(x, spec: str = "g") -> str:
    return "n/a" if x is None else format(x, spec)


def _value(v) -> str:
    """A setting as the report shows it: numbers %g, sequences as [a, b, c], text as is."""
    if isinstance(v, bool) or not isinstance(v, int | float | tuple | list):
        return str(v)
    if isinstance(v, tuple | list):
        return "[" + ", ".join(_value(a) for a in v) + "]"
    return format(v, "g")


def _cameras(metas, p0, centre) -> list[dict]:
    """Per image of one frame (its metadata): the camera's id, type, resolution, focal
    length, pixel pitch, f-number (and where it comes from), the angle of its optical axis
    to z, its azimuth and distance from the volume centre, its object-space pixel at the
    centre [mm] and the particles it images per pixel (``p0``: the frame's particles);
    None where the metadata does not say."""
    from mitpiv.errors import FileFormatError
    from mitpiv.io import camera_from_metadata
    from mitpiv.photometry import photometric_f_number

    out = []
    for meta in metas:
        cam = meta.get("camera") or {}
        res = cam.get("resolution")
        d = {"id": meta.get("sensor_id") or "?", "type": cam.get("type"), "resolution": res,
             "focal_length_mm": cam.get("focal_length_mm"), "pixel_pitch_um": cam.get("pixel_pitch_um"),
             "f_number": photometric_f_number(cam), "f_from": "", "axis_to_z": None, "azimuth": None,
             "distance": None, "pixel_mm": None, "ppp": None}
        if cam.get("f_number") is None and d["f_number"] is not None:  # where photometric_f_number found it
            d["f_from"] = " (photometric)" if cam.get("photometric_f_number") is not None else " (diffraction PSF)"
        axis = pos = None
        if cam.get("R") is not None and cam.get("position_mm") is not None:
            axis, pos = np.asarray(cam["R"], float)[2], cam["position_mm"]  # the optical axis (camera +z)
        elif cam.get("to_world_mitsuba") is not None:  # a plenoptic camera: its Mitsuba frame (z forward)
            m = np.asarray(cam["to_world_mitsuba"], float)
            axis, pos = m[:3, 2], m[:3, 3]
        if axis is not None:
            rel = np.asarray(pos, float) - np.asarray(centre, float)
            d["axis_to_z"] = float(np.degrees(np.arccos(min(1.0, abs(axis[2]) / np.linalg.norm(axis)))))
            d["azimuth"] = float(np.degrees(np.arctan2(rel[1], rel[0])))
            d["distance"] = float(np.linalg.norm(rel))
        try:
            c = camera_from_metadata(meta)
            if res:
                d["ppp"] = float(np.count_nonzero(c.visible(p0))) / (int(res[0]) * int(res[1]))
            if cam.get("type") == "plenoptic" and cam.get("mla_pitch_um") and cam.get("magnification"):
                # its lateral sample is a microlens, not a sensor pixel
                d["pixel_mm"] = float(cam["mla_pitch_um"]) * 1e-3 / float(cam["magnification"])
            else:
                s = np.linalg.svd(np.asarray(c.jacobian(np.asarray(centre, float).reshape(1, 3)))[0], compute_uv=False)
                d["pixel_mm"] = float(1.0 / np.sqrt(np.mean(np.square(s))))
        except FileFormatError:  # a sensor mitpiv does not model (Mitsuba's own): n/a
            pass
        out.append(d)
    return out


def _source_label(cfg) -> str:
    return "through the [sensor] model" if cfg.sensor is not None else "rendered (no sensor model)"


def _setup_lines(cfg, run: Path, metas, field, image_unit: str) -> tuple[list[str], float | None]:
    """The set-up section of a tomo report (its Markdown lines) from the experiment, the
    truth file, the images' metadata and the PIV field; and the cameras' mean object-space
    pixel at the volume centre [mm] (None where no camera gives one)."""
    from mitpiv.io import read_truth
    from mitpiv.studies.shared import grid_of

    grid = grid_of(cfg)
    truth = read_truth(run / "particles" / "truth.npz")
    p0 = np.asarray(truth["positions_mm"][0], float)
    dt = float(truth["times_s"][1]) - float(truth["times_s"][0])
    lo, hi = np.asarray(grid.origin_mm, float), np.asarray(grid.upper_mm, float)
    inside = int(np.all((p0 >= lo) & (p0 <= hi), axis=1).sum())
    nz, ny, nx = grid.shape
    vox = tuple(float(x) for x in grid.voxel_mm)
    vox_text = f"{vox[0]:g}" if len(set(vox)) == 1 else " x ".join(f"{x:g}" for x in vox)
    s, r, pv, pa = cfg.seeding, cfg.reconstruction, cfg.piv, cfg.particles
    flow = {k: val for k, val in cfg.flow.model_dump().items() if k not in ("kind", "dt_s") and val is not None}
    flow_text = ", ".join(f"{k} = {_value(val)}" for k, val in flow.items())
    d = np.asarray(truth["diameters_um"], float)
    if s.file is not None:
        diam = f"from {Path(s.file).name}"
    else:
        diam = f"{s.diameter_um:g} um {s.distribution}" + (
            f" (geometric std {s.geometric_std:g})" if s.distribution == "lognormal" else "")
    wins = [w if isinstance(w, tuple) else (w, w, w) for w in pv.windows]
    win_text = " -> ".join("x".join(str(a) for a in w) if len(set(w)) > 1 else str(w[0]) for w in wins)
    last_mm = " x ".join(f"{a * b:g}" for a, b in zip(wins[-1], vox, strict=True))
    spacing = ", ".join(f"{np.diff(c)[0]:g}" if len(c) > 1 else "-" for c in (field.x_mm, field.y_mm, field.z_mm))
    cams = _cameras(metas, p0, 0.5 * (lo + hi))
    pix = [c["pixel_mm"] for c in cams if c["pixel_mm"] is not None]
    pix = float(np.mean(pix)) if pix else None
    ppp = [c["ppp"] for c in cams]
    if all(p is not None for p in ppp) and ppp and max(ppp) - min(ppp) <= 0.005 * max(ppp):
        ppp_text = f"{np.mean(ppp):.4f} (every camera)"
    else:
        ppp_text = ", ".join(f"{c['id']} {_num(c['ppp'], '.4f')}" for c in cams)
    if pa.threshold_of == "robust":
        ref = "the robust peak level (99.99th percentile of the local maxima, at least the 50th brightest)"
    else:
        ref = "the volume maximum"
    rec = r.method + (f", {r.iterations} iterations, relaxation {r.mu:g}" if r.method in ("mart", "smart", "drt-mart")
                      else "")
    lines = ["## Set-up", "", "| quantity | value |", "|---|---|",
             f"| volume (reconstructed) | x {lo[0]:g} .. {hi[0]:g}, y {lo[1]:g} .. {hi[1]:g}, z {lo[2]:g} .. {hi[2]:g} "
             f"mm |",
             f"| voxel size | {vox_text} mm |",
             f"| grid | {nx} x {ny} x {nz} voxels (x, y, z) |",
             f"| time between the frames dt | {dt * 1e3:g} ms |",
             f"| particles | {len(p0)} seeded, {inside} inside the volume; diameter {diam}: {d.min():.2f} .. "
             f"{d.max():.2f} um |",
             f"| image density (ppp: particles per pixel) | {ppp_text} |",
             f"| flow | {cfg.flow.kind}: {flow_text} |",
             f"| images | {len(metas)} cameras, {_source_label(cfg)}; pixel values: {image_unit} |",
             f"| object-space pixel (cameras' mean, volume centre) | {_num(pix, '.4f')} mm = "
             f"{_num(None if pix is None else pix / max(vox), '.2f')} voxels |",
             f"| reconstruction | {rec} |",
             f"| particle detection | {pa.method}; local maxima above {pa.threshold_rel:g} x {ref} (threshold_of = "
             f"'{pa.threshold_of}'); matched to the truth within {pa.radius_voxels:g} voxels "
             f"({pa.radius_voxels * max(vox):g} mm) |",
             f"| PIV | windows {win_text} voxels (last {last_mm} mm), overlap {100 * pv.overlap:g} %, "
             f"{'deformed' if pv.deform else 'shifted'} windows; {field.n_vectors} vectors, {spacing} mm apart "
             f"(x, y, z) |",
             "", "| camera | type | resolution [px] | focal length [mm] | pixel pitch [um] | f-number | "
             "axis to z [deg] | azimuth [deg] | distance [mm] | object pixel [mm] | ppp |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for c in cams:
        res = c["resolution"]
        lines.append(f"| {c['id']} | {c['type'] or 'n/a'} | {f'{res[0]} x {res[1]}' if res else 'n/a'} | "
                     f"{_num(c['focal_length_mm'])} | {_num(c['pixel_pitch_um'])} | {_num(c['f_number'])}{c['f_from']} | "
                     f"{_num(c['axis_to_z'], '.1f')} | {_num(c['azimuth'], '.1f')} | {_num(c['distance'], '.0f')} | "
                     f"{_num(c['pixel_mm'], '.4f')} | {_num(c['ppp'], '.4f')} |")
    lines += ["", "Axis to z: the angle between a camera's optical axis and the z axis; azimuth: the camera's "
              "direction from the volume centre in the x-y plane (from +x towards +y); object pixel: one pixel's "
              "size in the volume at its centre (a plenoptic camera's: one microlens, its pitch over the "
              "magnification); ppp: the frame-0 particles a camera images, per pixel.", ""]
    return lines, pix


def _triple(v, spec: str, scale: float | np.ndarray = 1.0) -> str:
    """'x / y / z' of a 3-vector (each divided by ``scale``), n/a where it has no value."""
    if v is None or any(a is None for a in v):
        return "n/a"
    s = np.broadcast_to(np.asarray(scale, float), (3,))
    return " / ".join(format(float(a) / float(b), spec) for a, b in zip(v, s, strict=True))


def tomo_report(cfg, run_dir, results: dict, timings: dict) -> Report:
    """The report of a tomo run: the set-up (volume, voxel size, dt, particles and ppp,
    flow, cameras, reconstruction, detection, PIV), sensor images, volume projections and
    slices, the sub-aperture mosaic of a plenoptic camera, particle errors and the particles
    in 3D, the measured flow (a plane of measured and true vectors beside the error, chosen
    by ``[report]``; profiles of u, v, w), velocity errors, and tables with every error in
    voxels and in physical units."""
    from mitpiv.studies.shared import fmt_metric as f
    from mitpiv.studies.shared import grid_of, images, source_of, volume

    run = Path(run_dir)
    source = source_of(cfg)
    imgs, metas, files = images(run, 0, source)
    vol = volume(run, 0)
    grid = grid_of(cfg)
    field, _, ref, _, _, _ = _flow_data(run)
    rep = getattr(cfg, "report", None)
    axis, pos = (rep.slice_axis, rep.slice_mm) if rep is not None else ("auto", None)
    plane = flow_slice_plane(field, ref, axis, pos)
    unit = field.units
    if axis == "auto":
        per = "1/s" if unit == "mm/s" else "1/frame"
        sp, om = plane["mean_in_plane"], plane["mean_vorticity"]
        how = "auto: the mid-plane of the most in-plane " + ("rotation" if plane["by"] == "vorticity" else "motion")
        how_long = ("[report] slice_axis = 'auto': of the three mid-planes of the true window-averaged flow the one "
                    + ("with the largest mean |vorticity| normal to it" if plane["by"] == "vorticity" else
                       "with the largest mean in-plane speed (the flow has no vorticity)")
                    + "; mean |vorticity| " + ", ".join(f"{a} {om[a]:.3g}" for a in "zyx") + f" {per}, mean in-plane "
                    "speed " + ", ".join(f"{a} {sp[a]:.3g}" for a in "zyx") + f" {unit}")
    else:
        how = f"slice_axis = '{axis}'" + ("" if pos is None else f", slice_mm = {pos:g}")
        how_long = f"[report] {how}: " + ("the PIV plane nearest it" if pos is not None else "the middle PIV plane")
    image_unit = intensity_unit(metas[0] if metas else None)
    figures = {"sensor_images.png": _sensor_images(imgs, files, metas),
               "volume_projections.png": _volume_projections(vol, grid),
               "volume_slices.png": _volume_slices(vol, grid)}
    plen = [f for f, m in zip(files, metas, strict=True) if (m.get("camera") or {}).get("type") == "plenoptic"]
    if plen:
        figures["subaperture_mosaic.png"] = _mosaic(plen[0])
    figures["particle_errors_0.png"] = _particle_errors(run, 0)
    figures["particle_errors_1.png"] = _particle_errors(run, 1)
    figures["particles_3d.png"] = _particles_3d(run, cfg, 0)
    figures["flow_slice.png"] = _flow_slice(run, plane, how)
    figures["velocity_profiles.png"] = _velocity_profiles(run)
    figures["velocity_error.png"] = _velocity_error(run)
    setup, pix = _setup_lines(cfg, run, metas, field, image_unit)
    vox = np.asarray(grid.voxel_mm, float)
    ev, pv = results["evaluate"], results["piv"]
    lines = [f"# {cfg.name}", "", f"Scene `{Path(cfg.scene.xml).name}`, seed {cfg.seed}, "
             f"method {cfg.reconstruction.method}.", "", *setup, "## Reconstruction and particles", "",
             "| frame | Q | Q* | Q' | SNR | found | detected | ghosts | detection threshold |",
             "|---|---|---|---|---|---|---|---|---|"]
    for frame in (0, 1):
        m = ev[f"frame{frame}"]
        pr = m["particles"]
        pct = {k: None if pr.get(k) is None else 100 * pr[k] for k in ("detection_rate", "ghost_fraction")}
        thr, ref_i, of = pr.get("threshold"), pr.get("threshold_reference"), pr.get("threshold_of")
        if thr is None:
            thr_text = "n/a (not recorded by this run's evaluate stage)"
        elif ref_i is None:
            thr_text = f"{thr:.3g} ({of})"
        else:
            thr_text = f"{thr:.3g} = {cfg.particles.threshold_rel:g} x {ref_i:.3g} ({of})"
        q_rank = m["Q'"]
        lines.append(f"| {frame} | {f(m['Q'], '.3f')} | {f(m['Q*'], '.3f')} | {f(q_rank, '.3f')} | "
                     f"{f(m['SNR'], '.1f')} | {pr.get('n_found', 'n/a')} of {pr.get('n_truth', 'n/a')} | "
                     f"{f(pct['detection_rate'], '.1f')} % | {f(pct['ghost_fraction'], '.1f')} % | {thr_text} |")
    lines += ["", "Detection threshold: [particles] threshold_rel x the reference that threshold_of names, found "
              "per frame (reconstructed intensity, a.u. as in the volume figures).", "",
              "Position error of the matched particles (found - true), x / y / z:", "",
              "| frame | statistic | [voxels] | [mm] | [px] |", "|---|---|---|---|---|"]
    for frame in (0, 1):
        pr = ev[f"frame{frame}"]["particles"]
        for name, label, spec in (("bias", "bias", "+.3f"), ("rms", "RMS", ".3f"), ("u95", "u95 (1.96 sigma)", ".3f")):
            mm = pr.get(f"{name}_mm")
            vx = pr.get(f"{name}_vox")
            lines.append(f"| {frame} | {label} | {_triple(vx, spec)} | {_triple(mm, spec.replace('3', '4'))} | "
                         f"{_triple(mm, spec, pix) if pix else 'n/a'} |")
    lines += ["", f"1 voxel = {' x '.join(f'{v:g}' for v in vox)} mm; 1 px = {_num(pix, '.4f')} mm (the cameras' mean "
              "object-space pixel at the volume centre).", ""]
    r, b = pv.get("rms_vox") or [None] * 3, pv.get("bias_vox") or [None] * 3
    rp, bp = pv.get("rms") or [None] * 3, pv.get("bias") or [None] * 3
    per = "voxels/frame" if unit == "mm/s" else "voxels"
    ratio = None if pv.get("outlier_ratio") is None else 100 * pv["outlier_ratio"]
    speed = np.linalg.norm(ref, axis=-1)
    top = float(np.nanmax(speed)) if np.isfinite(speed).any() else None
    to_vox = (float(vox.max()) / field.dt_s) if field.dt_s else float(vox.max())
    lines += ["## 3D PIV", "", f"{pv['n']} vectors, outlier ratio {f(ratio, '.2f')} %; largest true speed "
              f"(window average) {_num(top, '.3g')} {unit} = {_num(None if top is None else top / to_vox, '.3g')} "
              f"{per}.", "",
              "| | u | v | w |", "|---|---|---|---|",
              f"| RMS error [{per}] | {f(r[0], '.4f')} | {f(r[1], '.4f')} | {f(r[2], '.4f')} |",
              f"| RMS error [{unit}] | {f(rp[0], '.3f')} | {f(rp[1], '.3f')} | {f(rp[2], '.3f')} |",
              f"| bias [{per}] | {f(b[0], '+.4f')} | {f(b[1], '+.4f')} | {f(b[2], '+.4f')} |",
              f"| bias [{unit}] | {f(bp[0], '+.3f')} | {f(bp[1], '+.3f')} | {f(bp[2], '+.3f')} |", "",
              f"1 voxel/frame = {' x '.join(f'{v:g}' for v in vox)} mm / dt"
              + (f" = {to_vox:g} mm/s." if field.dt_s else "."), ""]
    why = {**{k: v for fr in (0, 1) for k, v in (ev[f"frame{fr}"].get("null_reasons") or {}).items()},
           **(pv.get("null_reasons") or {})}
    if why:  # n/a in the tables: say why
        lines += ["Metrics without a value (n/a):", ""] + [f"- `{k}`: {v}" for k, v in why.items()] + [""]
    lines += ["## Wall time per stage", ""]
    lines += _timings_table(timings)
    lines += [""]
    for name in figures:
        lines += [f"![{name[:-4].replace('_', ' ')}]({name})", ""]
        if name == "flow_slice.png":
            lines += [f"flow_slice.png: the plane {plane['axis']} = {plane['position_mm']:+.2f} mm ({how_long}).", ""]
    return Report("\n".join(lines), figures)


# --------------------------------------------------------------------------- backlit
def _backlit_images(raw, det):
    def draw(path):
        plt = _plt()
        fig, ax = plt.subplots(1, 2, figsize=(11, 5))
        ax[0].imshow(raw, cmap="gray")
        ax[0].set_title("raw plenoptic image, frame 0")
        ax[1].imshow(det["min_map"], cmap="gray", vmin=0, vmax=1.2)
        ax[1].plot(det["uv_px"][:, 0], det["uv_px"][:, 1], "r+", ms=8, label="detections")
        ax[1].set_title("minimum transmittance over the focal stack")
        ax[1].legend(loc="upper right")
        fig.tight_layout()
        save_figure(fig, path)

    return draw


def _backlit_errors(errors, d_true_mm):
    def draw(path):
        plt = _plt()
        fig, ax = plt.subplots(1, 2, figsize=(11, 4))
        ax[0].hist(errors["depth_error_diameters"], bins=30)
        ax[0].set_xlabel("depth error [droplet diameters]")
        ax[0].set_ylabel("droplets")
        dt_ = d_true_mm[errors["pairs"][:, 1]]
        ax[1].plot(dt_, dt_ + errors["size_error_mm"], "o", ms=4)
        lim = [0, float(d_true_mm.max()) * 1.1]
        ax[1].plot(lim, lim, "k--", lw=1)
        ax[1].set_xlabel("true diameter [mm]")
        ax[1].set_ylabel("measured diameter [mm]")
        fig.tight_layout()
        save_figure(fig, path)

    return draw


def backlit_report(cfg, run_dir, results: dict, timings: dict) -> Report:
    """The report of a backlit run: raw image, minimum map with detections, depth-error
    histogram, size scatter, detection and tracking tables."""
    from mitpiv.io import read_exr, read_npz, read_truth
    from mitpiv.io.backlit import read_detections

    run = Path(run_dir)
    truth = read_truth(run / "field" / "truth.npz")
    raw = read_exr(run / "render" / "raw_frame000.exr")[0]
    det = read_detections(run / "detect" / "detections_0.npz")
    errors = read_npz(run / "evaluate" / "errors_0.npz")
    figures = {"images.png": _backlit_images(raw, det),
               "errors.png": _backlit_errors(errors, truth["diameters_um"] / 1e3)}
    ev = results["evaluate"]
    cal = results["calibrate"]
    lines = [f"# {cfg.name}: backlit plenoptic droplet tracking", "",
             f"{results['field']['n_particles']} droplets ({cfg.field.kind}), dewarp residual "
             f"{cal['dewarp_rms_mm'] * 1e3:.1f} um over {cal['markers']} dots.", "",
             "| frame | found | detected | lateral RMS [d] | depth RMS [d] | size bias [mm] | size RMS [mm] |",
             "|---|---|---|---|---|---|---|"]
    for k in (0, 1):
        f = ev[f"frame{k}"]
        lines.append(f"| {k} | {f['n_found']} | {f['detected_fraction']:.2f} | {f['lateral_rms_diameters']:.3f} | "
                     f"{f['depth_rms_diameters']:.3f} | {f['size_bias_mm']:.4f} | {f['size_rms_mm']:.4f} |")
    t = ev["tracking"]
    lines += ["", f"Tracking: {t['n']} pairs, {t['n_correct']} correct ({t['tracked_fraction']:.2f} of the droplets, "
              f"outlier ratio {t['outlier_ratio']:.2f}); velocity RMS x, y, z = "
              f"{', '.join(f'{v:.1f}' for v in t['rms'])} mm/s.", "", *_timings_table(timings), "",
              "![images](images.png)", "", "![errors](errors.png)", ""]
    return Report("\n".join(lines), figures)


# -------------------------------------------------------------------------- tracking
def _tracks_by_error(tracks, err, lo, hi):
    """Tracks in two slabs through the box centre (x-y: the middle quarter of z; x-z: the
    middle quarter of y), each sample coloured by its velocity error."""
    def draw(path):
        from matplotlib.collections import LineCollection

        plt = _plt()
        fig, axs = plt.subplots(1, 2, figsize=(11, 4.2))
        p = tracks.positions_mm
        ok = np.all(np.isfinite(p), axis=2)
        e = np.where(ok, err, np.nan)
        finite = np.isfinite(e)
        vmax = float(np.percentile(e[finite], 98)) if finite.any() else 1.0
        seg = ok[:, 1:] & ok[:, :-1]  # consecutive samples of one track: one line segment
        mid, quarter = 0.5 * (lo + hi), 0.125 * (hi - lo)
        sc = None
        for ax, (i, j, k, name) in zip(axs, ((0, 1, 2, "y"), (0, 2, 1, "z")), strict=True):
            near = ok & (np.abs(np.nan_to_num(p[..., k], nan=np.inf) - mid[k]) <= quarter[k])
            s_ok = seg & near[:, 1:] & near[:, :-1]
            lines = np.stack([p[:, :-1][s_ok][:, [i, j]], p[:, 1:][s_ok][:, [i, j]]], axis=1)
            ax.add_collection(LineCollection(lines, colors="0.7", linewidths=0.6, zorder=1))
            ghost = near & ~finite
            ax.scatter(p[ghost][:, i], p[ghost][:, j], s=6, c="red", marker="x", lw=0.6, zorder=2,
                       label="no velocity error (unmatched or track end)")
            good = near & finite
            sc = ax.scatter(p[good][:, i], p[good][:, j], s=5, c=e[good], cmap="viridis", vmin=0, vmax=vmax or None,
                            zorder=3)
            ax.set_xlim(lo[i], hi[i])
            ax.set_ylim(lo[j], hi[j])
            ax.set_xlabel("x [mm]")
            ax.set_ylabel(f"{name} [mm]")
            ax.set_aspect("equal")
            ax.set_title(f"{'xyz'[k]} within {mid[k] - quarter[k]:.2f} .. {mid[k] + quarter[k]:.2f} mm", fontsize=9)
        axs[0].legend(fontsize=7, loc="upper right")
        fig.colorbar(sc, ax=axs, label="|v - v_true| [mm/s]", shrink=0.8)
        fig.suptitle(f"{tracks.n_tracks} tracks (slabs through the box centre), coloured by velocity error",
                     fontsize=10)
        save_figure(fig, path)

    return draw


def _yield_per_frame(y, g):
    def draw(path):
        plt = _plt()
        fig, ax = plt.subplots(figsize=(6, 3.5))
        f = np.arange(len(y))
        ax.plot(f, 100 * np.asarray(y, float), "o-", ms=3, label="yield (true particles found)")
        ax.plot(f, 100 * np.asarray(g, float), "s-", ms=3, label="ghost fraction (of particles found)")
        ax.set_xlabel("frame")
        ax.set_ylabel("%")
        ax.set_ylim(-2, 102)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        fig.tight_layout()
        save_figure(fig, path)

    return draw


def _track_lengths(hist, true_hist=None):
    def draw(path):
        from matplotlib.ticker import MaxNLocator

        plt = _plt()
        h = np.asarray(hist, float)
        fig, ax = plt.subplots(figsize=(6, 3.5))
        ax.bar(np.arange(h.size), h, width=0.8, label="tracks found")
        if true_hist is not None:
            t = np.asarray(true_hist, float)
            ax.step(np.arange(t.size), t, where="mid", color="k", lw=1.2, label="true particles (frames in the box)")
        ax.set_xlabel("track length [frames]")
        ax.set_ylabel("tracks")
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.grid(alpha=0.3, axis="y")
        ax.legend(fontsize=8, loc="upper left")
        fig.tight_layout()
        save_figure(fig, path)

    return draw


def _true_lengths(run: Path, lo, hi):
    """Histogram of the frames each true particle spends in the measurement box."""
    from mitpiv.io import read_truth

    p = read_truth(run / "field" / "truth.npz")["positions_mm"]
    inside = np.all(np.isfinite(p), axis=2) & np.all((np.nan_to_num(p, nan=np.inf) >= lo) & (np.nan_to_num(
        p, nan=np.inf) <= hi), axis=2)
    n = inside.sum(axis=0)
    return np.bincount(n[n > 0])


def tracking_report(cfg, run_dir, results: dict, timings: dict) -> Report:
    """The report of a tracking run: the cameras' images of the first frame, the tracks
    coloured by their velocity error, yield and ghost fraction per frame, the track-length
    histogram and the LPT Challenge's metrics."""
    from mitpiv.io import read_npz
    from mitpiv.studies.shared import bounds_of, frame_files, frame_images, read_tracks
    from mitpiv.studies.shared import fmt_metric as f

    run = Path(run_dir)
    imgs, _ = frame_images(run, 0)
    tracks = read_tracks(run / "track" / "tracks.npz")
    err = read_npz(run / "evaluate" / "errors.npz", what="errors")
    lo, hi = bounds_of(cfg)
    figures = {"images_frame0.png": _sensor_images(imgs, frame_files(run, 0)),
               "tracks_velocity_error.png": _tracks_by_error(tracks, err["velocity_error_mm_s"], lo, hi),
               "yield_per_frame.png": _yield_per_frame(err["yield_per_frame"], err["ghost_per_frame"]),
               "track_lengths.png": _track_lengths(err["length_histogram"], _true_lengths(run, lo, hi))}
    ev = results["evaluate"]
    fl = results["field"]

    def pct(x):
        return f(None if x is None else 100 * x, ".2f") + " %"

    lines = [f"# {cfg.name}", "", f"Scene `{Path(cfg.scene.xml).name}`, seed {cfg.seed}, flow `{cfg.flow.kind}`, "
             f"{cfg.sequence.frames} frames {cfg.flow.dt_s * 1e3:g} ms apart; {fl['n_particles']} particles in the box "
             f"({fl['n_identities']} identities, {fl['entered']} entered), image density {f(ev.get('ppp'), '.4f')} ppp; "
             f"{results['track']['method'].upper()} tracking.", "",
             "## LPT Challenge metrics (all frames)", "", "| metric | value |", "|---|---|",
             f"| yield (true particles found) | {pct(ev.get('yield'))} |",
             f"| ghost fraction | {pct(ev.get('ghost_fraction'))} |",
             f"| position error | {f(ev.get('position_error_px'), '.4f')} px, "
             f"{f(ev.get('position_error_mm'), '.5f')} mm |",
             f"| velocity error | {f(ev.get('velocity_error_mm_s'), '.3f')} mm/s ({pct(ev.get('velocity_error_rel'))} "
             f"of the RMS speed) |",
             f"| acceleration error | {f(ev.get('acceleration_error_mm_s2'), '.1f')} mm/s^2 "
             f"({pct(ev.get('acceleration_error_rel'))}) |",
             f"| correct tracks | {pct(ev.get('correct_track_fraction'))} |",
             f"| tracks, mean length | {ev.get('n_tracks')}, {f(ev.get('mean_track_length'), '.1f')} frames |",
             f"| Eulerian bins: RMS error of the mean velocity | {f(ev.get('binned_mean_error_mm_s'), '.3f')} mm/s |",
             f"| calibration error (fitted vs true cameras) | {f(ev.get('calibration_error_px'), '.3f')} px |",
             "", f"Matching radius {f(ev.get('match_radius_mm'), '.4f')} mm ({cfg.evaluate.radius_px:g} px).", ""]
    why = ev.get("null_reasons") or {}
    if why:
        lines += ["Metrics without a value (n/a):", ""] + [f"- `{k}`: {v}" for k, v in why.items()] + [""]
    lines += ["## Wall time per stage", "", *_timings_table(timings), ""]
    lines += [f"![{n[:-4].replace('_', ' ')}]({n})\n" for n in figures]
    return Report("\n".join(lines), figures)


# ---------------------------------------------------------------------------- sweeps
def plot_sweep(table, x: str, y: str, path, *, group: str | None = None) -> None:
    """PNG of metric ``y`` against parameter ``x`` (names as in the table, "param." optional),
    one line per value of ``group``.

    Points that share ``x`` (and ``group``) and differ only in ``seed`` (a sweep over
    ``seed``) are drawn as their mean with error bars of one standard deviation (ddof 1),
    the number of seeds in the legend; points that differ in another parameter are drawn
    one by one.
    """
    import pandas as pd

    from mitpiv.errors import ConfigError

    plt = _plt()
    df = table[table["status"] == "ok"] if "status" in table else table

    def col(name):
        for c in (name, f"param.{name}"):
            if c in table.columns:
                return c
        raise ConfigError(f"plot_sweep: no column {name!r}; the table has {sorted(table.columns)}.")

    cx, cy = col(x), col(y)
    numeric = pd.api.types.is_numeric_dtype(df[cx])
    cats = list(dict.fromkeys(df[cx]))  # a categorical x (e.g. labels) keeps the study's order
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    groups = [(None, df)] if group is None else list(df.groupby(col(group), sort=False))
    keys = [cx] + ([col(group)] if group is not None else [])
    others = [c for c in df.columns if c.startswith("param.") and c not in keys and c != "param.seed"]
    seeds_only = all(df.groupby(keys, sort=False)[c].nunique(dropna=False).max() <= 1 for c in others)
    repeats = 1
    for g, sub in groups:
        lab = None if g is None else f"{group} = {g}"
        if seeds_only:
            st = sub.groupby(cx, sort=False)[cy].agg(["mean", "std", "count"]).reset_index()
        else:
            st = pd.DataFrame({cx: sub[cx], "mean": sub[cy], "std": np.nan, "count": 1})
        if numeric:
            st = st.sort_values(cx)
        xs = st[cx] if numeric else [cats.index(v) for v in st[cx]]
        n = int(st["count"].max())
        repeats = max(repeats, n)
        if n > 1:
            ax.errorbar(xs, st["mean"], yerr=st["std"].fillna(0.0), fmt="o-" if numeric else "o", ms=6, capsize=3,
                        label=(lab + ", " if lab else "") + f"mean $\\pm$ 1 s.d. over {n} seeds")
        else:
            ax.plot(xs, st["mean"], "o-" if numeric else "o", ms=6 if numeric else 7, label=lab)
    if not numeric:
        ax.set_xticks(range(len(cats)), [str(c) for c in cats], rotation=30, ha="right", fontsize=8)
        ax.grid(True, axis="y", alpha=0.3)
    ax.set_xlabel(x)
    ax.set_ylabel(y)
    if group is not None or repeats > 1:
        ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, path, dpi=110)


# ------------------------------------------------------------------ accuracy versus time
def _pareto(rows, stage: str):
    """The log-log error-against-time plot of one stage, its Pareto front dashed."""
    from mitpiv.studies.shared import pareto_front

    pts = [r for r in rows if r.stage == stage and not r.knob.startswith("reference") and r.error > 0]

    def draw(path):
        plt = _plt()
        fig, ax = plt.subplots(figsize=(7, 4.6))
        knobs = list(dict.fromkeys(r.knob for r in pts))
        for k in knobs:
            sub = [r for r in pts if r.knob == k]
            ax.loglog([r.seconds for r in sub], [r.error for r in sub], "o-" if stage != "end_to_end" else "o",
                      label=k)
            for r in sub:
                label = r.knob if stage == "end_to_end" else r.value
                ax.annotate(label, (r.seconds, r.error), textcoords="offset points", xytext=(4, 3), fontsize=7)
        front = pareto_front([r.seconds for r in pts], [r.error for r in pts])
        fp = sorted((r.seconds, r.error) for r, f in zip(pts, front, strict=True) if f)
        ax.plot(*zip(*fp, strict=True), "k--", lw=0.8, alpha=0.6, label="Pareto front")
        ax.set_xlabel("wall time [s]")
        ax.set_ylabel(pts[0].metric)
        ax.set_title(f"{stage}: error against time")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
        fig.tight_layout()
        save_figure(fig, path, dpi=110)

    return draw if pts else None


def accuracy_report(rows, *, title: str, intro: str, stages) -> Report:
    """The accuracy-versus-time report (:mod:`mitpiv.studies.accuracy`): per stage a table
    of every knob's setting, time and error, and its Pareto plot."""
    lines, figures = [f"# {title}", "", intro, ""], {}
    for stage in stages:
        sub = [r for r in rows if r.stage == stage]
        if not sub:
            continue
        lines += [f"## {stage}", "", f"| knob | value | time [s] | {sub[0].metric} | note |", "|---|---|---|---|---|"]
        lines += [f"| {r.knob} | {r.value} | {r.seconds:.2f} | {r.error:.3g} | {r.note} |" for r in sub]
        lines += ["", f"![{stage}](pareto_{stage}.png)", ""]
        draw = _pareto(rows, stage)
        if draw is not None:
            figures[f"pareto_{stage}.png"] = draw
    return Report("\n".join(lines), figures)
