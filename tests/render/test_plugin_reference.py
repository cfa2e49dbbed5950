"""The scene XML reference (docs page ``_generated/scene_xml``) is generated from the plugins'
module docstrings: the parser reads each ``name : type [unit], default X`` line of their
*Parameters* sections, so a parameter added to a docstring appears on the page, and every
property a plugin reads is on it."""

import re
from pathlib import Path

import pytest

from mitpiv.render import plugin_reference as R

PLUGINS = Path(R.__file__).resolve().parent / "plugins"

DOC = '''``toy``: a toy plugin.

Parameters
----------
alpha_mm : float [mm], default 2.5
    Length.
beta, gamma : integer; default 3, 4
    Two counts.
mode : string, default ``a``, one of ``a``, ``b``
    A mode.
eps : float, required, range (0, 1)
    A fraction.
near, far : float [mm]; default 0.01, 1e7
    Clips.
origin : point [mm]; default (0, 0, 0)
    A point.
psf_a, psf_b, psf_c : float [--, nm, --]; default f, 532, thin-lens M
    Three, each its own unit.
tol, n1, n2 : float, int; default 1e-3, 5, 8
    Types padded with the last one.
(nested phase) : phase, default isotropic
    Nested object.

Notes
-----
Not a parameter : no.

.. code-block:: xml

    <emitter type="toy">
        <float name="alpha_mm" value="1"/>
    </emitter>
'''


def _by_name(params):
    return {p.name: p for p in params}


def test_parser_reads_type_unit_default_range_and_groups():
    p = _by_name(R.parse_parameters(DOC))
    assert list(p) == ["alpha_mm", "beta", "gamma", "mode", "eps", "near", "far", "origin", "psf_a", "psf_b", "psf_c",
                       "tol", "n1", "n2", "(nested phase)"]
    assert (p["alpha_mm"].type, p["alpha_mm"].unit, p["alpha_mm"].default) == ("float", "mm", "2.5")
    assert p["alpha_mm"].description == "Length."
    assert (p["beta"].type, p["beta"].default, p["gamma"].default) == ("integer", "3", "4")
    assert p["beta"].description == p["gamma"].description == "Two counts."
    assert p["mode"].default == "``a``" and p["mode"].range == "one of ``a``, ``b``"
    assert p["eps"].required == "required" and p["eps"].default is None and p["eps"].range == "(0, 1)"
    assert (p["near"].default, p["far"].default, p["far"].unit) == ("0.01", "1e7", "mm")
    assert p["origin"].default == "(0, 0, 0)" and p["origin"].type == "point"  # commas inside brackets kept
    assert [p[k].unit for k in ("psf_a", "psf_b", "psf_c")] == ["--", "nm", "--"]
    assert [p[k].default for k in ("psf_a", "psf_b", "psf_c")] == ["f", "532", "thin-lens M"]
    assert [p[k].type for k in ("tol", "n1", "n2")] == ["float", "int", "int"]
    assert p["(nested phase)"].type == "phase"
    doc = R.parse_plugin_docstring(DOC, module="toy")
    assert doc.name == "toy" and doc.summary == "a toy plugin."
    assert '<float name="alpha_mm" value="1"/>' in doc.xml_example


def test_a_parameter_added_to_a_docstring_is_listed():
    """The page follows the docstrings: a new line in a real plugin's table is on the page."""
    src = (PLUGINS / "particle_tracer.py").read_text()
    doc = R.module_docstring(src)
    added = doc.replace("occlusion : boolean", "new_knob_mm : float [mm], default 3.5, range > 0\n"
                        "    A knob added for the test.\nocclusion : boolean")
    names = [p.name for p in R.parse_parameters(doc)]
    assert "new_knob_mm" not in names
    params = _by_name(R.parse_parameters(added))
    assert list(params) == ["rays_per_particle", "new_knob_mm", "occlusion", "batch_rays"]
    knob = params["new_knob_mm"]
    assert (knob.type, knob.unit, knob.default, knob.range) == ("float", "mm", "3.5", "> 0")
    page = R.reference_page([R.parse_plugin_docstring(added, module="particle_tracer", kind="integrator")])
    row = next(line for line in page.splitlines() if "`new_knob_mm`" in line)
    assert "3.5" in row and "mm" in row and "> 0" in row and "A knob added for the test." in row


@pytest.fixture(scope="module")
def page():
    return R.reference_page()


def _row(page, name):
    rows = [line for line in page.splitlines() if line.startswith(f"| `{name}` |")]
    assert rows, f"{name} is not on the page"
    return rows


def test_real_page_lists_every_plugin_and_the_key_parameters(page):
    docs = R.plugin_docs()
    assert [(d.name, d.kind) for d in docs] == [
        ("distorted_pinhole", "sensor"), ("plenoptic", "sensor"), ("laser_sheet", "emitter"),
        ("tracer_particles", "emitter"), ("mie", "phase"), ("particle_tracer", "integrator")]
    for d in docs:
        assert f"## `{d.name}`" in page
        assert d.parameters and d.xml_example, d.name
    # each with its default
    for sensor_row in _row(page, "azimuth_deg"):  # distorted_pinhole's and plenoptic's
        cells = [c.strip() for c in sensor_row.split("|")]
        assert cells[2:5] == ["float", "deg", "required for a placement"], cells
    assert all("(0, 0, 0)" in row for row in _row(page, "target"))
    assert "``psf_f_number``" not in page and "`psf_f_number`" in _row(page, "photometric_f_number")[0]
    assert "required" in _row(page, "mla_pitch_um")[0] and "um" in _row(page, "mla_pitch_um")[0]
    for row in _row(page, "irradiance"):  # laser_sheet's and tracer_particles'
        assert "1.0" in row and "W/mm^2" in row
    assert "16" in _row(page, "rays_per_particle")[0] and ">= 1" in _row(page, "rays_per_particle")[0]
    assert "placement.png" in page
    assert "```xml" in page


def _read_properties(src: str) -> set[str]:
    """Every property name a plugin's source reads through its PropertyReader."""
    names = set(re.findall(r'\brd\.(?:float|int|bool|string|vector|object|has)\("(\w+)"', src))
    if "self._place(rd, props)" in src:  # the pose: to_world or a placement (_props.read_placement)
        placement = (PLUGINS / "_props.py").read_text()
        names |= {"to_world"} | set(re.findall(r'\brd\.(?:float|vector)\("(\w+)"', placement))
    return names


def test_every_property_a_plugin_reads_is_documented():
    for d in R.plugin_docs():
        src = (PLUGINS / f"{d.module}.py").read_text()
        read = _read_properties(src)
        documented = {p.name for p in d.parameters}
        assert read, d.name
        assert not read - documented, (d.name, sorted(read - documented))


def test_placement_figure_script_draws_the_committed_figure(tmp_path):
    """docs/figures/make_placement_figure.py (the page's figure) still runs on place_camera."""
    import importlib.util

    script = Path(__file__).resolve().parents[2] / "docs" / "figures" / "make_placement_figure.py"
    assert script.with_name("placement.png").is_file()
    spec = importlib.util.spec_from_file_location("make_placement_figure", script)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    mod.main(tmp_path / "placement.png")
    assert (tmp_path / "placement.png").stat().st_size > 10_000
