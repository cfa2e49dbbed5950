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

__all__ = ["Report", "write", "tomo_report", "backlit_report", "accuracy_report", "save_figure", "plot_sweep"]


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


def tomo_report(cfg, run_dir, results: dict, timings: dict) -> Report:
    """The report of a tomo run: sensor images, volume projections and slices, the
    sub-aperture mosaic of a plenoptic camera, particle and velocity errors, and tables."""
    from mitpiv.studies.kinds.tomo import fmt_metric as f
    from mitpiv.studies.kinds.tomo import grid_of, images, source_of, volume

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


# ---------------------------------------------------------------------------- sweeps
def plot_sweep(table, x: str, y: str, path, *, group: str | None = None) -> None:
    """PNG of metric ``y`` against parameter ``x`` (names as in the table, "param." optional),
    one line per value of ``group``."""
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
    for g, sub in groups:
        lab = None if g is None else f"{group} = {g}"
        if numeric:
            sub = sub.sort_values(cx)
            ax.plot(sub[cx], sub[cy], "o-", label=lab)
        else:
            ax.plot([cats.index(v) for v in sub[cx]], sub[cy], "o", ms=7, label=lab)
    if not numeric:
        ax.set_xticks(range(len(cats)), [str(c) for c in cats], rotation=30, ha="right", fontsize=8)
        ax.grid(True, axis="y", alpha=0.3)
    ax.set_xlabel(x)
    ax.set_ylabel(y)
    if group is not None:
        ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, path, dpi=110)


# ------------------------------------------------------------------ accuracy versus time
def _pareto(rows, stage: str):
    """The log-log error-against-time plot of one stage, its Pareto front dashed."""
    from mitpiv.studies.accuracy import pareto_front

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
