"""Lazy Mitsuba variant: importing mitpiv selects nothing; the first render does.

The import-time checks run in fresh interpreters (this test session selected a variant in
tests/conftest.py). The expected default is decided independently of mitpiv, by asking
Dr.Jit whether it has a CUDA backend (``drjit.has_backend``): ``cuda_ad_mono`` if so,
else ``llvm_ad_mono``.
"""

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import mitsuba as mi
import numpy as np
import pytest

import mitpiv
from mitpiv.errors import ConfigError
from mitpiv.io import write_particles_ply
from mitpiv.render.plugins import PLUGINS
from mitpiv.render.scene import load_dict, load_scene
from mitpiv.render.variant import SUPPORTED, ensure_variant

from .helpers import particle_scene_xml

ROOT = Path(__file__).resolve().parents[2]  # the checkout whose mitpiv is under test

SCENE = particle_scene_xml("""    <sensor type="distorted_pinhole" id="cam">
        <float name="azimuth_deg" value="30"/>
        <float name="elevation_deg" value="50"/>
        <float name="distance_mm" value="600"/>
        <float name="focal_length_mm" value="85"/>
        <float name="pixel_pitch_um" value="20"/>
        <film type="hdrfilm">
            <integer name="width" value="16"/>
            <integer name="height" value="16"/>
            <string name="pixel_format" value="luminance"/>
        </film>
    </sensor>
""")

# A sensor given by plain numbers (no Mitsuba value, which would need a variant).
SENSOR = ('{"type": "distorted_pinhole", "azimuth_deg": 0.0, "elevation_deg": 90.0, "distance_mm": 300.0, "focal_length_mm": 50.0, '
          '"pixel_pitch_um": 20.0, "film": {"type": "hdrfilm", "width": 16, "height": 16, "pixel_format": "luminance"}}')

# What each entry point runs in a fresh interpreter, after `import mitpiv` (variable `xml`).
ENTRIES = {
    "load_scene": "from mitpiv.render.scene import load_scene\nload_scene(xml)",
    "load_dict": f"from mitpiv.render.scene import load_dict\nload_dict({{'type': 'scene', 'sensor': {SENSOR}}})",
    "target_scene": (f"import numpy as np\nfrom mitpiv.physics.targets import CalibrationTarget\n"
                     f"from mitpiv.render.targets import target_scene\n"
                     f"target_scene([{SENSOR}], CalibrationTarget('dots', 3, 3, 2.0), np.eye(4))"),
    "plugin module": "import mitpiv.render.plugins.laser_sheet",
}


def run_python(code: str, *, env_extra=None, cwd=None) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != "MITPIV_VARIANT"}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT)] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
    env.update(env_extra or {})
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], env=env, cwd=cwd, capture_output=True,
                          text=True, timeout=300)


@pytest.fixture(scope="module")
def expected_default():
    """The default variant, from Dr.Jit's own report of its backends (not from mitpiv)."""
    r = run_python("import drjit as dr; print('cuda_ad_mono' if dr.has_backend(dr.JitBackend.CUDA) else 'llvm_ad_mono')")
    assert r.returncode == 0, r.stderr
    return r.stdout.strip()


@pytest.fixture
def xml(tmp_path):
    write_particles_ply(tmp_path / "particles_0.ply", np.zeros((1, 3)), 1.0, proxy_radius_mm=0.01)
    path = tmp_path / "scene.xml"
    path.write_text(SCENE)
    return path


def test_import_selects_no_variant_and_imports_no_mitsuba():
    r = run_python("""
        import json, sys
        import mitpiv
        after_mitpiv = [m for m in ("mitsuba", "drjit") if m in sys.modules]
        lazy = callable(mitpiv.io.read_exr) and hasattr(mitpiv.physics, "__path__")  # subpackages on first use
        import mitpiv.physics, mitpiv.io, mitpiv.imaging, mitpiv.lightfield, mitpiv.reconstruct, mitpiv.analysis
        import mitpiv.holography, mitpiv.progress, mitpiv.render, mitpiv.render.variant
        after_numpy_parts = [m for m in ("mitsuba", "drjit") if m in sys.modules]
        print(json.dumps({"after_mitpiv": after_mitpiv, "after_numpy_parts": after_numpy_parts, "lazy": lazy,
                          "current": mitpiv.render.variant.current_variant()}))
    """)
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert out == {"after_mitpiv": [], "after_numpy_parts": [], "lazy": True, "current": None}


@pytest.mark.parametrize("entry", list(ENTRIES))
def test_first_render_entry_selects_default_variant_and_registers_plugins(entry, xml, expected_default):
    code = "\n".join([
        "import json, logging, sys",
        "logging.basicConfig(level=logging.INFO, stream=sys.stderr)",
        "import mitpiv",
        f"xml = {str(xml)!r}",
        "assert 'mitsuba' not in sys.modules",
        ENTRIES[entry],
        "import mitsuba as mi",
        f"mods = {{n: getattr(sys.modules.get('mitpiv.render.plugins.' + n), '_VARIANT', None) for n in {PLUGINS!r}}}",
        "print(json.dumps({'variant': mi.variant(), 'plugins': mods}))",
    ])
    r = run_python(code)
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout.strip().splitlines()[-1])
    assert out["variant"] == expected_default
    assert out["plugins"] == {n: expected_default for n in PLUGINS}  # every plugin built for that variant
    assert f"Mitsuba variant {expected_default} selected" in r.stderr  # logged at INFO


def test_mitpiv_variant_environment_overrides_the_default(xml):
    r = run_python(f"""
        from mitpiv.render.scene import load_scene
        import mitsuba as mi
        load_scene({str(xml)!r})
        print(mi.variant())
    """, env_extra={"MITPIV_VARIANT": "llvm_ad_mono"})
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "llvm_ad_mono"


def test_unsupported_mitpiv_variant_is_a_config_error_naming_the_variable(xml, monkeypatch):
    monkeypatch.setenv("MITPIV_VARIANT", "scalar_rgb")
    before = mi.variant()
    for call in (ensure_variant, mitpiv.set_variant, lambda: load_scene(xml), lambda: load_dict({"type": "scene"})):
        with pytest.raises(ConfigError, match=r"MITPIV_VARIANT='scalar_rgb'.*llvm_ad_mono, cuda_ad_mono"):
            call()
    assert mi.variant() == before  # nothing was switched
    # An explicit name does not consult the environment
    assert mitpiv.set_variant(before) == before


def test_import_with_bad_mitpiv_variant_does_not_fail():
    r = run_python("import mitpiv, sys; print('mitsuba' in sys.modules)", env_extra={"MITPIV_VARIANT": "scalar_rgb"})
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "False"


def test_ensure_variant_keeps_a_supported_variant_and_replaces_an_unsupported_one(xml):
    before = mi.variant()
    assert before in SUPPORTED  # selected by tests/conftest.py
    try:
        assert ensure_variant() == before and mi.variant() == before
        mi.set_variant("llvm_ad_rgb")  # not usable by mitpiv's plugins
        assert load_scene(xml).sensors()[0].describe()["type"] == "distorted_pinhole"
        assert mi.variant() == before  # the default again (conftest chose the same default)
    finally:
        mitpiv.set_variant(before)
