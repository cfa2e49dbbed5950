"""The documentation builds with warnings as errors (``make docs``), and its generated pages
hold what they are generated from: the experiment schema of every kind, every example with
its source, the API of the VTK writers, the plugins' parameter tables.

The README is the landing page and these tests keep it honest: its two commands are the
Makefile's, the demo's scores are the measured ones, its Python example runs and prints what
it shows, its links reach files (and headings) that exist and pages of the site, its
replication tallies are the committed reports', and every ``mitpiv`` subcommand it or the
pages moved out of it name exists."""

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_docs_build_without_warnings(tmp_path):
    r = subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-E", "-q", "-b", "html",
                        str(ROOT / "docs"), str(tmp_path)], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr[-4000:]
    schema = (tmp_path / "_generated" / "schema.html").read_text()
    from mitpiv.studies.kinds import KINDS, get_kind

    for kind in KINDS:
        for table in get_kind(kind).schema.model_fields:
            assert table in schema, (kind, table)
    examples = (tmp_path / "_generated" / "examples.html").read_text()
    for script in (ROOT / "examples").glob("[!_]*.py"):
        assert script.stem.replace("_", " ") in examples, script.name
    api = (tmp_path / "api.html").read_text()
    assert "write_image_data" in api and "export_vtk" in api and "run_experiment" in api
    # the modules the guide describes are on the API page, the plugins with their parameter tables
    for name in ("rays_per_particle", "focus_plane_normal", "apply_sensor_set", "calibrate_mla", "drt_mart",
                 "hybrid_detect", "calibrate_dewarp", "calibrate_otf", "compare_value", "ring_energies"):
        assert name in api, name
    # the scene XML reference: every plugin's parameters from its docstring, the placement figure
    xml_ref = (tmp_path / "_generated" / "scene_xml.html").read_text()
    for name in ("distorted_pinhole", "plenoptic", "laser_sheet", "tracer_particles", "particle_tracer",
                 "azimuth_deg", "elevation_deg", "distance_mm", "sheet_normal", "photometric_f_number",
                 "psf_magnification", "mla_pitch_um", "irradiance", "rays_per_particle", "tolerance"):
        assert f"<code class=\"docutils literal notranslate\"><span class=\"pre\">{name}</span></code>" in xml_ref, name
    assert "placement.png" in xml_ref and (tmp_path / "_images" / "placement.png").is_file()
    assert "scene_xml.html" in (tmp_path / "index.html").read_text()
    guide = (tmp_path / "guide.html").read_text()
    assert "Shake-The-Box" in guide and "api.html" in guide
    assert "ParaView" in (tmp_path / "getting-started.html").read_text()


# ------------------------------------------------------------------ the README, a landing page
README = ROOT / "README.md"


def _slug(heading: str) -> str:
    """GitHub's anchor of a Markdown heading (what a `#...` link must name)."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def _anchors(text: str) -> set[str]:
    return {_slug(h) for h in re.findall(r"^#{1,6} (.+)$", text, re.M)}


def _local_links(text: str) -> list[str]:
    return [t for t in re.findall(r"\]\(([^)\s]+)\)", text) if not re.match(r"[a-z]+:", t)]


def test_readme_commands_are_the_makefile_targets():
    """The two commands, as the README gives them, are the Makefile's targets, each doing the
    set-up first; make demo runs the experiment and writes the report the README points at."""
    text, make = README.read_text(), (ROOT / "Makefile").read_text()
    for target in ("demo", "test"):
        assert re.search(rf"^    make {target}\b", text, re.M), f"README lost `make {target}`"
        assert re.search(rf"^{target}: setup$", make, re.M), f"Makefile target {target} no longer does set-up"
    assert re.search(r"^demo: setup\n\t\$\(PY\) -m mitpiv\.cli run scenes/tomo4/experiment\.toml --out \$\(OUT\)$",
                     make, re.M) and re.search(r"^OUT \?= out/tomo4$", make, re.M)
    assert re.search(r"^test: setup\n\t\$\(PY\) -m pytest", make, re.M)
    assert "scenes/tomo4/experiment.toml" in text and "out/tomo4/report/report.md" in text
    # the figures the README says the report holds are the ones the report writes
    report_src = (ROOT / "mitpiv" / "studies" / "report.py").read_text()
    figures = re.findall(r"`(\w+\.png)`", text)
    assert "flow_slice.png" in figures
    for fig in figures:
        assert f'"{fig}"' in report_src, f"the README names {fig}, which the run report does not write"


def test_readme_demo_numbers_are_the_measured_ones():
    """The demo's scores in the README are those bench/bench_demo.py measured (block `demo` of
    docs/benchmarks.md, the numbers the speed table's end-to-end row comes from)."""
    text = README.read_text()
    head = text.index("| Q (frame 0 / 1) |")
    row = text[head:].splitlines()[2]
    q0, q1, d0, d1, _g0, _g1, _vectors, _outliers, u, v, w = (float(x) for x in re.findall(r"\d+(?:\.\d+)?", row))
    sys.path.insert(0, str(ROOT / "bench"))
    import docblocks

    block = docblocks.read_block((ROOT / "docs" / "benchmarks.md").read_text(), "demo")
    m = re.search(r"ours: Q ([\d.]+) / ([\d.]+), detected ([\d.]+) % / ([\d.]+) %, PIV RMS error ([\d.]+) / ([\d.]+) / "
                  r"([\d.]+) voxel", block)
    assert m, "docs/benchmarks.md's demo block no longer states the demo's metrics"
    bq0, bq1, bd0, bd1, bu, bv, bw = (float(x) for x in m.groups())
    assert abs(q0 - bq0) <= 6e-4 and abs(q1 - bq1) <= 6e-4, (row, m.group(0))
    assert (d0, d1) == (bd0, bd1) and max(abs(u - bu), abs(v - bv), abs(w - bw)) <= 6e-5, (row, m.group(0))


def test_readme_library_example_runs(tmp_path, monkeypatch, capsys):
    """The README's Python example runs as printed, from a folder that has the repository's
    scenes, and prints what the README shows (within what another machine's float32
    rendering may move)."""
    text = README.read_text()
    blocks = re.findall(r"^```python\n(.*?)^```$", text, re.S | re.M)
    assert len(blocks) == 1, "the README has one Python example; test each one added"
    (tmp_path / "scenes").symlink_to(ROOT / "scenes", target_is_directory=True)
    monkeypatch.chdir(tmp_path)
    exec(compile(blocks[0], str(README), "exec"), {"__name__": "readme_example"})
    printed = capsys.readouterr().out
    assert (tmp_path / "out" / "readme" / "report" / "report.md").is_file()

    def numbers(out: str):
        head = re.search(r"^tomo4: Q ([\d.]+), particles detected ([\d.]+) %, PIV RMS error", out, re.M)
        mlos = re.search(r"^MLOS: Q ([\d.]+)$", out, re.M)
        assert head and mlos, out
        return float(head.group(1)), float(head.group(2)), float(mlos.group(1))

    shown = numbers("\n".join(line[4:] for line in text.splitlines() if line.startswith("    ")))
    got = numbers(printed)
    assert abs(got[0] - shown[0]) < 0.03 and abs(got[1] - shown[1]) < 5 and abs(got[2] - shown[2]) < 0.03, (got, shown)


def test_readme_links_point_at_pages_that_exist():
    """Every relative link of the README names a file of the repository (and a heading of it,
    where it names one); every docs page it links is a page of the site."""
    text = README.read_text()
    links = _local_links(text)
    assert any(t.startswith("docs/") for t in links)
    index = (ROOT / "docs" / "index.md").read_text()
    for link in links:
        path, _, anchor = link.partition("#")
        target = ROOT / path if path else README
        assert target.exists(), f"README links {link}, which does not exist"
        if anchor:
            assert anchor in _anchors(target.read_text()), f"README links {link}: no such heading"
        rel = Path(path)
        if rel.suffix == ".md" and rel.parts[0] == "docs" and len(rel.parts) == 2 and rel.stem != "benchmarks":
            assert re.search(rf"^{rel.stem}$", index, re.M), f"{path} is linked from the README but not in the toctree"


def test_readme_replication_tallies_are_the_committed_reports():
    """The physics-row tallies in the README (and in the guide) are the first lines of the
    committed replication reports, one row per report."""
    reports = {p.parent.name: p for p in (ROOT / "docs" / "replications").glob("*/report.md")}
    pattern = re.compile(r"^\| ([a-z-]+) \| (\d+) / (\d+) / (\d+) of (\d+) \| (\d+) / (\d+) / (\d+) \|", re.M)
    for page in (README, ROOT / "docs" / "guide.md"):
        rows = {r[0]: [int(x) for x in r[1:]] for r in pattern.findall(page.read_text())}
        assert set(rows) == set(reports), (page.name, sorted(rows), sorted(reports))
        for name, (agree, disagree, inconclusive, n, inputs, definitions, info) in rows.items():
            first = reports[name].read_text().splitlines()[0]
            m = re.search(r"(\d+) of (\d+) physics rows agree, (\d+) disagree, (\d+) inconclusive.*not counted: (\d+) "
                          r"input, (\d+) definition, (\d+) info", first)
            assert m, (name, first)
            assert [int(x) for x in m.groups()] == [agree, n, disagree, inconclusive, inputs, definitions, info], (
                f"{page.name}'s {name} row is not the committed report's tally: {first}")


def test_commands_named_in_readme_and_guide_exist():
    """Every `mitpiv SUBCOMMAND` the README and the moved pages name is a subcommand of the CLI."""
    r = subprocess.run([sys.executable, "-m", "mitpiv.cli", "--help"], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    subcommands = set(re.search(r"\{([a-z,-]+)\}", r.stdout).group(1).split(","))
    for page in (README, *(ROOT / "docs" / f for f in ("guide.md", "scenes.md", "performance.md",
                                                         "getting-started.md"))):
        named = set(re.findall(r"(?:`|bin/)mitpiv ([a-z][a-z-]*)", page.read_text()))
        assert named, page.name
        assert named <= subcommands, (page.name, named - subcommands)
