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
def _image_row(panels, *, size: float = 3.2, axes: bool = False):
    """A figure writer: one row of images; ``panels`` = [(image, title, imshow keywords)]."""
    def draw(path):
        plt = _plt()
        fig, axs = plt.subplots(1, len(panels), figsize=(size * len(panels), size), squeeze=False)
        for ax, (img, title, kw) in zip(axs[0], panels, strict=True):
            ax.imshow(img, **kw)
            ax.set_title(title, fontsize=9)
            if not axes:
                ax.axis("off")
        fig.tight_layout()
        save_figure(fig, path)

    return draw


def _top(img, q: float) -> float | None:
    """The colour-scale maximum: the q-th percentile (a few bright pixels would hide the rest)."""
    return float(np.percentile(img, q)) or None


def _sensor_images(imgs, files):
    return _image_row([(img, f.stem, {"cmap": "gray", "vmax": _top(img, 99.9)}) for img, f in zip(imgs, files,
                                                                                                    strict=True)])


def _volume_projections(vol):
    pz, py = vol.max(axis=0), vol.max(axis=1)
    return _image_row([(pz, "frame 0 volume, max along z", {"cmap": "magma", "origin": "lower", "aspect": "equal",
                                                            "vmax": _top(pz, 99.5)}),
                       (py, "max along y", {"cmap": "magma", "origin": "lower", "aspect": "auto",
                                            "vmax": _top(py, 99.5)})], size=4.5, axes=True)


def _volume_slices(vol, grid):
    ks = np.linspace(0, vol.shape[0] - 1, 5).round().astype(int)
    kw = {"cmap": "magma", "origin": "lower", "vmax": _top(vol, 99.9)}
    return _image_row([(vol[k], f"z = {grid.z_mm[k]:+.2f} mm", kw) for k in ks], size=3.0)


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


def _flow_slice(run: Path):
    """Middle z slice of the PIV field: measured and true in-plane vectors over the
    out-of-plane vorticity (or the speed, where the true flow has none), and the error
    magnitude, on one colour scale per quantity."""
    def draw(path):
        plt = _plt()
        field, meas, ref, err, om, om_t = _flow_data(run)
        k = field.shape[0] // 2
        x, y, u = field.x_mm, field.y_mm, field.units
        ext = (*_extent(x), *_extent(y))
        speed_t = np.linalg.norm(ref[k], axis=-1)
        size = max(np.ptp(x), np.ptp(y), 1e-9)
        rotational = np.nanmax(np.abs(om_t[k, ..., 2])) > 0.05 * np.nanmax(speed_t) / size
        if rotational:
            bg = (om[k, ..., 2], om_t[k, ..., 2])
            lim = float(np.nanmax(np.abs(om_t[k, ..., 2])))
            kw = {"cmap": "RdBu_r", "vmin": -lim, "vmax": lim}
            label = "vorticity $\\omega_z$ [1/s]" if u == "mm/s" else "$\\omega_z$ [1/frame]"
        else:
            bg = (np.linalg.norm(meas[k], axis=-1), speed_t)
            kw = {"cmap": "viridis", "vmin": 0.0, "vmax": float(np.nanmax(speed_t)) or None}
            label = f"speed |u| [{u}]"
        step = max(1, int(np.ceil(max(x.size, y.size) / 20)))  # at most ~20 arrows per axis
        yy, xx = np.meshgrid(y[::step], x[::step], indexing="ij")
        scale = float(np.nanmax(speed_t)) or 1.0
        arrow = 1.2 * step * (x[1] - x[0] if x.size > 1 else size)  # the longest arrow spans ~1.2 arrow spacings
        # fixed axes (constrained layout would double the drawing time)
        fig = plt.figure(figsize=(14.5, 4.6))
        axs = [fig.add_axes((x0, 0.12, 0.25, 0.76)) for x0 in (0.04, 0.295, 0.685)]
        cax = [fig.add_axes((x0, 0.17, 0.009, 0.66)) for x0 in (0.555, 0.945)]
        for ax, b, vec, title in ((axs[0], bg[0], meas, "measured"), (axs[1], bg[1], ref, "true (window average)")):
            im = ax.imshow(b, origin="lower", extent=ext, interpolation="nearest", **kw)
            q = vec[k, ::step, ::step]
            ax.quiver(xx, yy, q[..., 0], q[..., 1], angles="xy", scale_units="xy", scale=scale / arrow,
                      width=0.004, color="k")
            ax.set_title(f"{title}, z = {field.z_mm[k]:+.2f} mm", fontsize=10)
        fig.colorbar(im, cax=cax[0], label=label)
        e = np.linalg.norm(err[k], axis=-1)
        im = axs[2].imshow(e, origin="lower", extent=ext, cmap="magma", interpolation="nearest",
                           vmin=0, vmax=float(np.nanpercentile(e, 99)) if np.isfinite(e).any() else None)
        out = field.outlier[k]
        if out.any():
            yo, xo = np.meshgrid(y, x, indexing="ij")
            axs[2].plot(xo[out], yo[out], "o", mfc="none", mec="c", ms=7, label="outlier")
            axs[2].legend(fontsize=8, loc="upper right")
        axs[2].set_title("|measured - true|", fontsize=10)
        fig.colorbar(im, cax=cax[1], label=f"error magnitude [{u}]")
        for ax in axs:
            ax.set_xlabel("x [mm]")
        axs[0].set_ylabel("y [mm]")
        axs[2].set_ylabel("y [mm]")
        axs[1].tick_params(labelleft=False)
        fig.suptitle(f"3D PIV, in-plane vectors (u, v) on the middle z plane; arrows: {u}, one scale", fontsize=10)
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
        a3.view_init(elev=22, azim=-60)
        a3.legend(fontsize=8, loc="upper left")
        a2.set_xlabel("x [mm]")
        a2.set_ylabel("z [mm] (depth)")
        a2.set_title("side view (x-z)", fontsize=10)
        fig.colorbar(sc, cax=cax, label=f"|found - true| [{unit}]")
        fig.suptitle(f"frame {frame}: detected vs true particles, coloured by position error"
                     f"{' (every ' + str(int(np.ceil(ok.sum() / MAX_3D_POINTS))) + 'th drawn)' if ok.sum() > MAX_3D_POINTS else ''}",
                     fontsize=10)
        save_figure(fig, path, dpi=100)

    return draw


def tomo_report(cfg, run_dir, results: dict, timings: dict) -> Report:
    """The report of a tomo run: sensor images, volume projections and slices, the
    sub-aperture mosaic of a plenoptic camera, particle errors and the particles in 3D, the
    measured flow (a slice of measured and true vectors beside the error, profiles of u, v,
    w), velocity errors, and tables."""
    from mitpiv.studies.shared import fmt_metric as f
    from mitpiv.studies.shared import grid_of, images, source_of, volume

    run = Path(run_dir)
    source = source_of(cfg)
    imgs, metas, files = images(run, 0, source)
    vol = volume(run, 0)
    figures = {"sensor_images.png": _sensor_images(imgs, files), "volume_projections.png": _volume_projections(vol),
               "volume_slices.png": _volume_slices(vol, grid_of(cfg))}
    plen = [f for f, m in zip(files, metas, strict=True) if (m.get("camera") or {}).get("type") == "plenoptic"]
    if plen:
        figures["subaperture_mosaic.png"] = _mosaic(plen[0])
    figures["particle_errors_0.png"] = _particle_errors(run, 0)
    figures["particle_errors_1.png"] = _particle_errors(run, 1)
    figures["particles_3d.png"] = _particles_3d(run, cfg, 0)
    figures["flow_slice.png"] = _flow_slice(run)
    figures["velocity_profiles.png"] = _velocity_profiles(run)
    figures["velocity_error.png"] = _velocity_error(run)
    ev, pv = results["evaluate"], results["piv"]
    lines = [f"# {cfg.name}", "", f"Scene `{Path(cfg.scene.xml).name}`, seed {cfg.seed}, "
             f"method {cfg.reconstruction.method}.", "", "## Reconstruction and particles", "",
             "| frame | Q | Q* | Q' | SNR | detected | ghosts | u95 x / y / z [voxels] |", "|---|---|---|---|---|---|---|---|"]
    for frame in (0, 1):
        m = ev[f"frame{frame}"]
        pr = m["particles"]
        u = pr.get("u95_vox") or [None] * 3
        pct = {k: None if pr.get(k) is None else 100 * pr[k] for k in ("detection_rate", "ghost_fraction")}
        q_rank = m["Q'"]
        lines.append(f"| {frame} | {f(m['Q'], '.3f')} | {f(m['Q*'], '.3f')} | {f(q_rank, '.3f')} | "
                     f"{f(m['SNR'], '.1f')} | {f(pct['detection_rate'], '.1f')} % | {f(pct['ghost_fraction'], '.1f')} % | "
                     f"{f(u[0], '.3f')} / {f(u[1], '.3f')} / {f(u[2], '.3f')} |")
    r, b = pv["rms_vox"] or [None] * 3, pv["bias_vox"] or [None] * 3
    ratio = None if pv.get("outlier_ratio") is None else 100 * pv["outlier_ratio"]
    lines += ["", "## 3D PIV", "", f"{pv['n']} vectors, outlier ratio {f(ratio, '.2f')} %.", "",
              "| | u | v | w |", "|---|---|---|---|",
              f"| RMS error [voxels] | {f(r[0], '.4f')} | {f(r[1], '.4f')} | {f(r[2], '.4f')} |",
              f"| bias [voxels] | {f(b[0], '+.4f')} | {f(b[1], '+.4f')} | {f(b[2], '+.4f')} |", ""]
    why = {**{k: v for fr in (0, 1) for k, v in (ev[f"frame{fr}"].get("null_reasons") or {}).items()},
           **(pv.get("null_reasons") or {})}
    if why:  # n/a in the tables: say why
        lines += ["Metrics without a value (n/a):", ""] + [f"- `{k}`: {v}" for k, v in why.items()] + [""]
    lines += ["## Wall time per stage", ""]
    lines += _timings_table(timings)
    lines += [""] + [f"![{f[:-4].replace('_', ' ')}]({f})\n" for f in figures]
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
