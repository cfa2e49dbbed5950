"""Paper-scale physically based rendering (issue 50, item 1): each replicated paper's camera
system rendered by Mitsuba with mitpiv's plugins at the paper's resolution and particle count,
beside Mitsuba's own ``perspective`` (and, for cameras with an aperture, ``thinlens``) sensor
rendering the same particles with the same integrator.

Per paper, in a process of its own (so its peak memory is its own):

* the particles of the paper scene's ``[seeding]`` at full scale, from the experiment engine;
* the scene load (the XML, the particle mesh, the Mie table);
* every camera rendered once per frame (``render_sensor``: the PSF convolution included),
  the first camera's time apart (it compiles the kernels), rays traced and rays per second;
* the Monte Carlo noise of cameras that sample an aperture: two renders with different seeds
  at each rung of a ladder of rays per particle, ``|a - b| / (sqrt 2 |(a + b) / 2|)`` (the
  relative L2 noise of one render), and its slope against the rays (-1/2 expected);
* the baselines on the same particles, pose and film: ``perspective`` (one ray per particle),
  and ``thinlens`` with the camera's aperture and focus at the same rays per particle; the
  ratio at equal noise is ``(t / t_base) (noise / noise_base)^2`` (rays needed scale as
  noise^2);
* the process's peak resident memory.

``python bench/bench_render_papers.py`` runs the four papers and writes the block
``render-papers`` of docs/benchmarks.md; ``--quick`` runs smaller crops in a few minutes (not
written to the docs unless ``--out`` is given); ``--only NAME`` runs one paper.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))


@dataclass
class Paper:
    """One paper's camera system: the experiment, its full-scale overrides, what to render."""

    title: str
    toml: str
    overrides: dict
    quick: dict  # overrides of the quick run (on top of ``overrides``)
    sensors: list[str] | None = None  # None: every sensor of the scene
    ladder: list[int] = field(default_factory=list)  # rays per particle for the noise ladder
    ladder_sensor: str | None = None
    ladder_quick: list[int] = field(default_factory=list)
    rays: dict = field(default_factory=dict)  # sensor id -> rays per particle, where not the scene's
    note: str = ""


def _box(half_x, half_y, half_z, y0=0.0):
    return {"seeding.box_min_mm": [-half_x, y0 - half_y, -half_z], "seeding.box_max_mm": [half_x, y0 + half_y, half_z]}


PAPERS = {
    "sapiv-distortion": Paper(
        title="SAPIV 5x5 array (Kubaczyk): 25 pinholes 1000^2 px, FFT PSF at 5x",
        toml="scenes/sapiv_paper/experiment.toml",
        overrides={},  # the thesis's system as committed: 50 x 50 x 10 mm at 4 / mm^3
        quick={"scene.params.resolution": 500, **_box(12.5, 12.5, 5.0)},
        sensors=None,
        note="pinholes: one ray per particle and camera, no Monte Carlo noise",
    ),
    "channel-tomo": Paper(
        title="channel tomo-PIV: 4 thin-lens cameras 1000^2 px, Mie droplets, FFT PSF at 5x",
        toml="scenes/channel/experiment.toml",
        # the committed 320 px crop widened to 1000 px (19 um pixels: 375+ wide, 100+ deep) and
        # 10^5 droplets (0.1 ppp): 10^5 / (11.325^2 x 3.02 mm^3)
        overrides={"scene.params.resolution": 1000, "seeding.concentration_per_mm3": 1e5 / (11.325**2 * 3.02),
                   **_box(5.6625, 5.6625, 1.51)},
        quick={"scene.params.resolution": 320, "seeding.concentration_per_mm3": 1e4 / (3.624**2 * 3.02),
               **_box(1.812, 1.812, 1.51)},
        ladder=[4, 16, 64], ladder_sensor="cam0", ladder_quick=[4, 16],
        note="the scene's 16 rays per particle through f/24.4 thin lenses",
    ),
    "lfpiv-vs-tomo": Paper(
        title="LF-PIV vs tomo (Shi et al.): 6600x4400 plenoptic (PMR 14 hex) + 4 tomo cameras 480x320",
        toml="scenes/lfpiv_tomo_paper/experiment.toml",
        overrides={"scene.params.lf_width": 6600, "scene.params.lf_height": 4400, "scene.params.lf_centre_y_mm": 0.0,
                   "scene.params.rays_per_particle": 200000, **_box(20.0, 14.0, 5.0)},
        quick={"scene.params.lf_width": 660, "scene.params.lf_height": 440, "scene.params.lf_centre_y_mm": 10.0,
               "seeding.box_min_mm": [-2.914, 7.724, -5.0], "seeding.box_max_mm": [2.914, 12.276, 5.0]},
        sensors=["plen", "t0", "t1", "t2", "t3"],
        rays={f"t{k}": 20000 for k in range(4)},  # the study's tomographic point
        ladder=[2000, 20000, 200000], ladder_sensor="plen", ladder_quick=[2000, 20000],
        note="the plenoptic camera at the scene's 200,000 rays per particle (the paper traces 5 million), the "
             "tomographic cameras (f/11 thin lenses) at the study's 20,000",
    ),
    "multi-plenoptic": Paper(
        title="multi-plenoptic (Fahringer & Thurow): 2 plenoptic 3280^2 px (328^2 lenslets)",
        toml="scenes/multiplenoptic_paper/experiment.toml",
        overrides={"scene.params.lenslets": 328, "scene.params.resolution": 3280, "scene.params.pin_resolution": 328,
                   "seeding.count": 2500, **_box(6.888, 6.888, 1.722)},
        quick={"scene.params.lenslets": 48, "scene.params.resolution": 480, "scene.params.pin_resolution": 48,
               "seeding.count": 54, **_box(1.008, 1.008, 1.722)},
        sensors=["plen0", "plen1"],
        ladder=[2000, 20000, 200000], ladder_sensor="plen0", ladder_quick=[2000, 20000],
        note="the scene's 20,000 rays per particle",
    ),
}


# ---------------------------------------------------------------------- one paper (child process)
def _relative_noise(a, b) -> float:
    """Relative L2 noise of one render from two independent ones: |a - b| / (sqrt 2 |mean|)."""
    a = np.asarray(a, np.float64)
    b = np.asarray(b, np.float64)
    m = np.linalg.norm(0.5 * (a + b))
    return float(np.linalg.norm(a - b) / (math.sqrt(2.0) * m)) if m > 0 else float("nan")


def _baseline_xml(xml_text: str, sensor, kind: str, rays: int | None) -> str:
    """The scene with its sensors replaced by Mitsuba's ``perspective`` / ``thinlens`` at the
    pose, field of view and film of ``sensor`` (a loaded mitpiv sensor)."""
    root = ET.fromstring(xml_text)
    for s in list(root.iter("sensor")):
        root.remove(s)
    if rays is not None:
        _with_rays(root, rays)
    cam = sensor.camera
    w, h = (int(v) for v in sensor.film().size())
    if sensor.class_name() == "Plenoptic" or type(sensor).__name__ == "Plenoptic":
        half = 0.5 * w * cam.pixel_pitch_um * 1e-3 / cam.image_distance_mm
        aperture, focus = cam.aperture_radius_mm, cam.focus_distance_mm
    else:
        half = 0.5 * w / cam.focal_px
        aperture = None if cam.f_number is None else 0.5 * cam.focal_length_mm / cam.f_number
        focus = cam.focus_distance_mm
    m = np.array(sensor.world_transform().matrix, dtype=np.float64).reshape(4, 4)
    el = ET.SubElement(root, "sensor", type=kind, id="base")
    tr = ET.SubElement(el, "transform", name="to_world")
    ET.SubElement(tr, "matrix", value=" ".join(f"{v:.9g}" for v in m.ravel()))
    ET.SubElement(el, "float", name="fov", value=f"{math.degrees(2 * math.atan(half)):.9g}")
    ET.SubElement(el, "string", name="fov_axis", value="x")
    ET.SubElement(el, "float", name="near_clip", value="0.01")
    ET.SubElement(el, "float", name="far_clip", value="1e7")
    if kind == "thinlens":
        ET.SubElement(el, "float", name="aperture_radius", value=f"{aperture:.9g}")
        ET.SubElement(el, "float", name="focus_distance", value=f"{focus:.9g}")
    film = ET.SubElement(el, "film", type="hdrfilm")
    ET.SubElement(film, "integer", name="width", value=str(w))
    ET.SubElement(film, "integer", name="height", value=str(h))
    ET.SubElement(film, "string", name="pixel_format", value="luminance")
    rf = sensor.film().rfilter().class_name()
    ET.SubElement(film, "rfilter", type={"BoxFilter": "box", "CatmullRomFilter": "catmullrom",
                                         "GaussianFilter": "gaussian", "TentFilter": "tent"}.get(rf, "box"))
    return _text(root)


def _text(root) -> str:
    """The XML of ``root`` without the ``<default>`` entries nothing uses any more (load_scene
    refuses them)."""
    text = ET.tostring(root, encoding="unicode")
    for d in list(root.iter("default")):
        if d.get("name") != "frame" and f"${d.get('name')}" not in text:
            root.remove(d)
    return ET.tostring(root, encoding="unicode")


def _with_rays(root, rays: int):
    for integ in root.iter("integrator"):
        for c in list(integ):
            if c.get("name") == "rays_per_particle":
                integ.remove(c)
        ET.SubElement(integ, "integer", name="rays_per_particle", value=str(rays))


def _used(params: dict, xml_path: Path) -> dict:
    """The ``$name`` parameters the scene file uses (load_scene refuses unused ones)."""
    text = xml_path.read_text()
    return {k: v for k, v in params.items() if f"${k}" in text}


def _timed_render(sc, sensor, seed):
    import drjit as dr

    from mitpiv.render.render import render_sensor

    dr.sync_thread()
    t0 = time.perf_counter()
    img = render_sensor(sc, sensor, seed=seed)
    dt = time.perf_counter() - t0
    stats = dict(getattr(sc.integrator(), "last_stats", {}) or {})
    return img, dt, int(stats.get("splats", 0))


def run_one(name: str, quick: bool, tmp: Path) -> dict:
    import mitpiv  # noqa: F401
    from mitpiv.render.variant import ensure_variant

    ensure_variant()
    from mitpiv.render.scene import load_scene
    from mitpiv.studies.experiment import load_experiment
    from mitpiv.studies.runner import run_experiment

    paper = PAPERS[name]
    over = dict(paper.overrides)
    if quick:
        over.update(paper.quick)
    toml = ROOT / paper.toml
    cfg = load_experiment(toml, over)
    t0 = time.perf_counter()
    run_experiment(toml, tmp / "run", overrides=over, until="particles", progress=False)
    t_seed = time.perf_counter() - t0
    scene_dir = tmp / "scene"
    scene_dir.mkdir()
    xml = Path(cfg.scene.xml)
    shutil.copy(xml, scene_dir / xml.name)
    for f in (tmp / "run" / "particles").glob("particles_*.ply"):
        shutil.copy(f, scene_dir / f.name)
    params = dict(cfg.scene.params or {})
    t0 = time.perf_counter()
    sc = load_scene(scene_dir / xml.name, frame=0, params=params)
    t_load = time.perf_counter() - t0
    ids = [s.id() for s in sc.sensors() if paper.sensors is None or s.id() in paper.sensors]
    n_particles = sum(int(np.array(e.particle_arrays()[2]).size)
                      for e in sc.integrator().particle_emitters(sc))
    xml_text = (scene_dir / xml.name).read_text()

    def variant(tag, rays=None, no_psf=None):
        """The scene with other rays per particle and/or one camera's PSF off."""
        root = ET.fromstring(xml_text)
        if rays is not None:
            _with_rays(root, rays)
        for el in root.iter("sensor"):
            if el.get("id") == no_psf:
                for q in list(el):
                    if q.get("name", "").startswith("psf_"):
                        el.remove(q)
                    elif q.get("name") == "psf":
                        q.set("value", "none")
        path = scene_dir / f"{tag}.xml"
        path.write_text(_text(root))
        return load_scene(path, frame=0, params=_used(params, path))

    cams, objs = [], {}
    groups = {}
    for sid in ids:  # cameras the paper renders with other rays than the scene's
        groups.setdefault(paper.rays.get(sid), []).append(sid)
    for rays, sids in groups.items():
        scg = sc if rays is None else variant(f"rays{rays}", rays=rays)
        for s in scg.sensors():
            if s.id() not in sids:
                continue
            img, dt, n_rays = _timed_render(scg, s, seed=1000 + len(cams))
            w, h = (int(v) for v in s.film().size())
            cams.append({"id": s.id(), "type": type(s).__name__, "px": [w, h], "seconds": dt, "rays": n_rays,
                         "rays_per_particle": scg.integrator().rays_for(s), "nonzero": float(np.mean(img > 0)),
                         "psf": getattr(getattr(s, "psf", None), "mode", None)})
            objs[s.id()] = (scg, s)
            print(f"  {name}: {s.id()} {w}x{h} {dt:.2f} s, {n_rays / 1e6:.3g} M rays", flush=True)
    out = {"paper": name, "title": paper.title, "note": paper.note, "quick": quick, "overrides": over,
           "particles": n_particles, "seed_seconds": t_seed, "load_seconds": t_load, "cameras": cams}
    warm, noise = {}, {}  # sensor id -> warm seconds / relative noise at its own rays

    def pair(scx, sx, seeds):
        """Two renders: the later one's time (warm) and the noise of one render."""
        a, _, n_rays = _timed_render(scx, sx, seed=seeds[0])
        b, tb, _ = _timed_render(scx, sx, seed=seeds[1])
        return tb, _relative_noise(a, b), n_rays

    # Monte Carlo noise against rays per particle (the rung at the camera's own rays reuses
    # the loaded scene: its warm time and noise)
    ladder = paper.ladder_quick if quick else paper.ladder
    rows = []
    for rays in ladder:
        own = next((c for c in cams if c["id"] == paper.ladder_sensor and c["rays_per_particle"] == rays), None)
        scl = objs[own["id"]][0] if own else variant("ladder", rays=rays)
        sl = [x for x in scl.sensors() if x.id() == paper.ladder_sensor][0]
        t, nz, n_rays = pair(scl, sl, (21, 22))
        rows.append({"rays_per_particle": rays, "seconds": t, "rays": n_rays, "noise": nz})
        if own:
            warm[own["id"]], noise[own["id"]] = t, nz
        print(f"  {name}: ladder {rows[-1]}", flush=True)
        del scl, sl
    if len(rows) > 1:
        r = np.array([x["rays_per_particle"] for x in rows], float)
        nz = np.array([x["noise"] for x in rows], float)
        out["noise_slope"] = float(np.polyfit(np.log(r), np.log(nz), 1)[0])
    out["ladder"] = rows

    # baselines: each kind of camera against Mitsuba's perspective (pinholes) or thinlens (an
    # aperture: the same rays per particle); a camera with an FFT PSF also without it
    base, seen = [], set()
    for c in cams:
        key = (c["type"], tuple(c["px"]), c["psf"], c["rays_per_particle"])
        if key in seen:
            continue
        seen.add(key)
        scg, s = objs[c["id"]]
        rays = c["rays_per_particle"]
        if c["id"] not in warm:
            warm[c["id"]], nz, _ = pair(scg, s, (31, 32))
            if rays > 1:
                noise[c["id"]] = nz
        row = {"sensor": c["id"], "type": c["type"], "rays_per_particle": rays, "ours_seconds": warm[c["id"]],
               "ours_noise": noise.get(c["id"])}
        if c["psf"] == "fft":
            sc2 = variant("nopsf", rays=rays if rays > 1 else None, no_psf=c["id"])
            s2 = [x for x in sc2.sensors() if x.id() == c["id"]][0]
            row["ours_no_psf_seconds"] = pair(sc2, s2, (5, 6))[0]
            del sc2, s2
        kind = "thinlens" if rays > 1 else "perspective"
        path = scene_dir / f"{kind}.xml"
        path.write_text(_baseline_xml(xml_text, s, kind, rays if rays > 1 else None))
        scb = load_scene(path, frame=0, params=_used(params, path))
        sb = scb.sensors()[0]
        tb, nb, rb = pair(scb, sb, (8, 9))
        row.update(baseline=kind, baseline_seconds=tb, baseline_rays=rb, baseline_noise=nb if rays > 1 else None)
        del scb, sb
        base.append(row)
        print(f"  {name}: baseline {row}", flush=True)
    out["baselines"] = base
    cams[0]["seconds_warm"] = warm[cams[0]["id"]]
    out["peak_rss_gib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20
    return out


# ---------------------------------------------------------------------- the table
def _fmt_s(x):
    return "" if x is None else (f"{x:.2f} s" if x < 100 else f"{x:.0f} s")


def table(results: list[dict]) -> str:
    lines = ["| paper | particles | cameras | rays per particle | scene load | first camera (compiles) | "
             "per camera (warm) | per frame | rays/s | peak RSS |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        cams = r["cameras"]
        kinds = {}
        for c in cams:
            kinds.setdefault(f"{c['px'][0]}x{c['px'][1]} {c['type']}", []).append(c)
        cam_txt = "; ".join(f"{len(v)} x {k}" for k, v in kinds.items())
        rays = sum(c["rays"] for c in cams)
        frame = sum(c["seconds"] for c in cams[1:]) + cams[0].get("seconds_warm", cams[0]["seconds"])
        per_cam = "; ".join(f"{k.split()[0]}: {_fmt_s(np.median([c['seconds'] for c in v if c is not cams[0]] or [cams[0]['seconds_warm']]))}"
                            for k, v in kinds.items())
        rpp = "; ".join(sorted({f"{c['rays_per_particle']:,}" for c in cams}))
        lines.append(f"| {r['title']} | {r['particles']:,} | {cam_txt} | {rpp} | {_fmt_s(r['load_seconds'])} | "
                     f"{_fmt_s(cams[0]['seconds'])} | {per_cam} | {_fmt_s(frame)} | {rays / frame / 1e6:.1f} M | "
                     f"{r['peak_rss_gib']:.2f} GiB |")
    lines += ["", "Against Mitsuba's own sensors on the same particles, pose, film and integrator (warm): "
              "`perspective` for a pinhole (one ray per particle), `thinlens` with the camera's aperture and "
              "focus at the same rays per particle; noise: relative L2 of one render (two seeds); at equal "
              "noise: the time ratio times (noise / baseline noise)^2:", "",
              "| paper | camera | ours | ours without PSF | baseline | ratio | noise ours / baseline | "
              "ratio at equal noise |",
              "|---|---|---|---|---|---|---|---|"]
    for r in results:
        for b in r["baselines"]:
            ours, nop, t = b["ours_seconds"], b.get("ours_no_psf_seconds"), b["baseline_seconds"]
            noise, bn = b.get("ours_noise"), b.get("baseline_noise")
            eq = ours / t * (noise / bn) ** 2 if noise and bn else None
            lines.append(
                f"| {r['paper']} | {b['sensor']} ({b['type']}, {b['rays_per_particle']:,} rays) | {_fmt_s(ours)} | "
                f"{_fmt_s(nop) or '-'} | {b['baseline']} {_fmt_s(t)} | {ours / t:.2f}x"
                + (f" ({nop / t:.2f}x without PSF)" if nop else "") + " | "
                + (f"{noise:.3g} / {bn:.3g}" if noise and bn else "-") + " | "
                + (f"{eq:.2f}x" if eq else "-") + " |")
    lines += ["", "Monte Carlo noise of one render (relative L2, from two seeds) against rays per particle:", ""]
    for r in results:
        if not r.get("ladder"):
            continue
        cells = ", ".join(f"{x['rays_per_particle']:,}: {x['noise']:.3g} ({_fmt_s(x['seconds'])})" for x in r["ladder"])
        lines.append(f"- {r['paper']} ({r['ladder'][0] and PAPERS[r['paper']].ladder_sensor}): {cells}; "
                     f"slope {r['noise_slope']:.2f} (-0.5 expected)")
    lines.append("")
    for r in results:
        lines.append(f"- {r['paper']}: {r['note']}; particles seeded in {_fmt_s(r['seed_seconds'])}.")
    return "\n".join(lines) + "\n"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="the papers' crops (minutes)")
    ap.add_argument("--only", action="append", choices=sorted(PAPERS), help="run this paper (repeatable)")
    ap.add_argument("--out", default=None, help="Markdown page for the block (default docs/benchmarks.md "
                                                "for full runs, none for --quick)")
    ap.add_argument("--one", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--json", default=None, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.one:
        with tempfile.TemporaryDirectory(prefix="mitpiv-bench-render-") as d:
            res = run_one(a.one, a.quick, Path(d))
        Path(a.json).write_text(json.dumps(res))
        return 0
    from bench_speed import head_commit, machine

    commit = head_commit()
    names = a.only or list(PAPERS)
    results = []
    with tempfile.TemporaryDirectory(prefix="mitpiv-bench-render-") as d:
        for name in names:
            print(f"{name} ...", flush=True)
            js = Path(d) / f"{name}.json"
            t0 = time.perf_counter()
            cmd = [sys.executable, __file__, "--one", name, "--json", str(js)] + (["--quick"] if a.quick else [])
            subprocess.run(cmd, check=True, env={**os.environ, "PYTHONUNBUFFERED": "1"})
            results.append(json.loads(js.read_text()))
            print(f"{name}: {time.perf_counter() - t0:.0f} s", flush=True)
    cmd = "python bench/bench_render_papers.py" + (" --quick" if a.quick else "") + "".join(f" --only {n}" for n in a.only or [])
    body = f"`{cmd}`. Machine: {machine(commit)}.\n\n" + table(results)
    print(body)
    out = a.out or (None if a.quick else str(ROOT / "docs" / "benchmarks.md"))
    if out:
        import docblocks

        name = "render-papers" if not a.quick else "render-papers-quick"
        docblocks.update_file(out, name, body, heading="Rendering at the papers' scale (bench_render_papers.py)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
