"""The typed experiment schema: every key of every table of every scene's experiment file,
mistyped, gives one error that names the table, the key and the nearest valid name; every
mistyped value names the table, the key, the value and the valid choices or range; all of
it before any stage runs. The schema reference, --set values and the CLI flags come from
the same models."""

import shutil
import tomllib
import typing
from pathlib import Path

import pytest

from mitpiv.errors import ConfigError
from mitpiv.studies import load_experiment
from mitpiv.studies.kinds import KINDS, get_kind
from mitpiv.studies.schema import describe, parse_value

SCENES = Path(__file__).resolve().parents[2] / "scenes"
EXPERIMENTS = sorted(SCENES.glob("*/experiment.toml"))


def _tables(path):
    raw = tomllib.loads(path.read_text())
    return [(t, k, v) for t, tab in raw.items() if isinstance(tab, dict) for k, v in tab.items()]


@pytest.mark.parametrize("path", EXPERIMENTS, ids=lambda p: p.parent.name)
def test_every_mistyped_key_is_named_with_the_nearest_valid_one(path, tmp_path, monkeypatch):
    # nothing may render or write while the experiment is checked
    monkeypatch.setattr("mitpiv.studies.runner.run_stages", lambda *a, **k: pytest.fail("a stage ran"))
    for table, key, _value in _tables(path):
        if table == "scene" and key == "params":
            continue  # free-form $name substitutions of the scene XML
        raw = path.read_text()
        typo = key[:-1] if len(key) > 3 else key + "x"
        with pytest.raises(ConfigError) as e:
            load_experiment(_renamed(path, table, key, typo, tmp_path))
        msg = str(e.value)
        assert f"[{table}] {typo}: unknown key" in msg, msg
        assert f"Did you mean '{key}'" in msg, msg
        assert raw == path.read_text()


def _renamed(path, table, key, typo, tmp_path):
    """A copy of the experiment (beside the original, so relative paths hold) with
    ``table.key`` renamed ``table.typo``, as a user's typo would."""
    lines, section = [], None
    for line in path.read_text().splitlines():
        s = line.strip()
        if s.startswith("[") and s.endswith("]"):
            section = s.strip("[]").strip()
        if section == table and s.split("=")[0].strip() == key:
            line = line.replace(key, typo, 1)
        lines.append(line)
    folder = tmp_path / path.parent.name
    if not folder.exists():
        shutil.copytree(path.parent, folder, ignore=shutil.ignore_patterns("*.ply", "*.npz", "*.csv"))
    out = folder / "experiment.toml"
    out.write_text("\n".join(lines) + "\n")
    return out


@pytest.mark.parametrize("path", EXPERIMENTS, ids=lambda p: p.parent.name)
def test_every_bad_value_names_table_key_value_and_choices(path):
    kind = get_kind(tomllib.loads(path.read_text()).get("kind", "tomo"))
    model = kind.schema
    checked = 0
    for table, key, value in _tables(path):
        if table == "scene" or (table in ("flow", "field") and key == "kind"):
            continue
        ann = _field_annotation(model, table, key, tomllib.loads(path.read_text())[table])
        if typing.get_origin(ann) is typing.Literal:
            bad, want = "nonsense", [repr(c) for c in typing.get_args(ann)]
        elif isinstance(value, bool):
            bad, want = "maybe", []
        elif isinstance(value, int | float):
            bad, want = "abc", []
        else:
            continue
        with pytest.raises(ConfigError) as e:
            load_experiment(path, {f"{table}.{key}": bad})
        msg = str(e.value)
        assert f"[{table}] {key}" in msg and repr(bad) in msg, msg
        assert all(w in msg for w in want), msg
        checked += 1
    assert checked >= 4
    # flow / field kinds: the valid kinds are listed
    for table in ("flow", "field"):
        if table in tomllib.loads(path.read_text()):
            with pytest.raises(ConfigError, match=rf"\[{table}\] kind: 'vortexring' is not a valid choice; choose one of"):
                load_experiment(path, {f"{table}.kind": "vortexring"})


def _field_annotation(model, table, key, raw_table):
    from mitpiv.studies.schema import models_in

    members = models_in(model.model_fields[table].annotation)
    for m in members:
        kf = m.model_fields.get("kind")
        if kf is None or raw_table.get("kind") in typing.get_args(kf.annotation):
            ann = m.model_fields[key].annotation
            while typing.get_origin(ann) is typing.Union and type(None) in typing.get_args(ann):
                ann = [a for a in typing.get_args(ann) if a is not type(None)][0]
            return ann
    raise AssertionError(f"no model for [{table}]")


def test_method_choices_are_the_reconstruction_entry_points():
    from mitpiv.reconstruct.images import RECONSTRUCT_METHODS
    from mitpiv.studies.kinds.tomo import ReconstructionTable

    assert typing.get_args(ReconstructionTable.model_fields["method"].annotation) == RECONSTRUCT_METHODS


def test_flow_tables_follow_the_flow_classes():
    """The [flow] keys are the flow constructors' own parameters (plus dt_s): a table and
    the physics it configures cannot drift apart."""
    import inspect

    from mitpiv.physics.flows import FLOW_KINDS
    from mitpiv.studies.kinds.tomo import schema
    from mitpiv.studies.schema import models_in

    members = {typing.get_args(m.model_fields["kind"].annotation)[0]: m
               for m in models_in(schema().model_fields["flow"].annotation)}
    assert set(members) == set(FLOW_KINDS)
    for kind, cls in FLOW_KINDS.items():
        params = set(inspect.signature(cls).parameters)
        assert set(members[kind].model_fields) == params | {"kind", "dt_s"}


def test_models_are_frozen_and_defaults_filled():
    cfg = load_experiment(SCENES / "tomo4" / "experiment.toml")
    assert cfg.piv.deform is True and cfg.particles.radius_voxels == 2.0 and cfg.sensor is None
    with pytest.raises(Exception, match="frozen"):
        cfg.piv.overlap = 0.5  # type: ignore[misc]


def test_schema_reference_lists_every_table_and_field(capsys):
    from mitpiv.cli import main

    for kind in ("tomo", "backlit"):
        model = get_kind(kind).schema
        text = describe(model)
        for name in model.model_fields:
            assert f"`{name}`" in text or f"[{name}]" in text, name
        assert main(["schema", "--kind", kind]) == 0
        out = capsys.readouterr().out
        assert "| key | type | default | range | meaning |" in out
    out = describe(get_kind("tomo").schema)
    assert "`voxel_mm`" in out and "> 0" in out and "## [flow] kind = 'vortex_ring'" in out
    assert main(["schema", "--kind", "holo"]) == 2


@pytest.mark.parametrize("text, value", [("5", 5), ("0.1", 0.1), ("[48, 32]", [48, 32]), ("true", True),
                                         ("smart", "smart"), ('"a b"', "a b"), ("[[64, 64, 32]]", [[64, 64, 32]])])
def test_set_values_are_toml(text, value):
    assert parse_value(text) == value


def test_old_kind_name_and_unknown_kind(tmp_path):
    p = tmp_path / "e.toml"
    p.write_text((SCENES / "tomo4" / "experiment.toml").read_text().replace('name = "tomo4"',
                                                                            'name = "t"\nkind = "particles"'))
    p2 = tmp_path / "scene.xml"
    p2.write_text((SCENES / "tomo4" / "scene.xml").read_text())
    assert load_experiment(p).kind == "tomo"
    with pytest.raises(ConfigError, match="not a known experiment kind.*tomo.*backlit"):
        load_experiment(p, {"kind": "holography"})


def test_image_smoothing_is_a_checked_reconstruction_key():
    """[reconstruction] smooth_px reaches MART (default 0: off) and a negative sigma is refused
    by name before any stage runs."""
    path = SCENES / "tomo4" / "experiment.toml"
    assert load_experiment(path).reconstruction.smooth_px == 0.0
    assert load_experiment(path, {"reconstruction.smooth_px": 0.7}).reconstruction.smooth_px == 0.7
    with pytest.raises(ConfigError, match=r"\[reconstruction\] smooth_px"):
        load_experiment(path, {"reconstruction.smooth_px": -1.0})


def test_the_sensor_table_has_a_meaning_for_every_key():
    """The [sensor] table is generated from SensorModel's signature; each key's meaning comes
    from its docstring's Attributes section (it was empty for all of them)."""
    from mitpiv.studies.schema import docstring_meanings
    from mitpiv.studies.shared import sensor_table

    fields = sensor_table().model_fields
    assert {k for k, f in fields.items() if not f.description} == set()
    assert "per watt" in fields["exposure"].description and "[electrons RMS]" in fields["read_noise_e"].description
    for kind in ("tomo", "tracking"):  # both kinds that render take the one table
        assert "| `quantum_efficiency` | float | 1.0 |" in describe(get_kind(kind).schema)
    assert "Electrons per photon" in \
        describe(get_kind("tomo").schema)
    doc = "Title.\n\nParameters\n----------\na, b : float\n    Two lengths [mm],\n    in order.\nc : int\n\nNotes\n-----\nx : y\n"
    assert docstring_meanings(doc) == {"a": "Two lengths [mm], in order.", "b": "Two lengths [mm], in order.",
                                       "c": "int"}


def _empty_meanings(model, where: str = "") -> list[str]:
    """Every field, at every depth of ``model`` (each member of a union of tables included),
    whose meaning (pydantic ``description``) is empty, as ``table<Member>.key``."""
    from mitpiv.studies.schema import models_in

    out = []
    for name, fi in model.model_fields.items():
        key = f"{where}.{name}" if where else name
        if not (fi.description or "").strip():
            out.append(key)
        members = models_in(fi.annotation)
        for m in members:
            out += _empty_meanings(m, f"{key}<{m.__name__}>" if len(members) > 1 else key)
    return out


@pytest.mark.parametrize("kind", KINDS)
def test_every_schema_field_of_every_kind_has_a_meaning(kind, capsys):
    """`mitpiv schema` gives every key of every table a meaning: the flow tables' keys (from
    the flow classes' numpydoc Parameters sections) and the [field] tables' (from the droplet
    generators') were all empty."""
    from mitpiv.cli import main

    assert _empty_meanings(get_kind(kind).schema) == []
    assert main(["schema", "--kind", kind]) == 0
    rows = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("| `")]
    assert rows and [ln for ln in rows if ln.endswith("|  |")] == []


def test_flow_meanings_carry_units():
    """The meanings name the physics and its unit as the flow code uses it."""
    from mitpiv.studies.schema import models_in
    from mitpiv.studies.shared import flow_union

    flows = {typing.get_args(m.model_fields["kind"].annotation)[0]: m.model_fields
             for m in models_in(flow_union())}
    assert "[mm^2/s]" in flows["burgers"]["circulation_mm2_s"].description
    assert "[1/s]" in flows["burgers"]["strain_rate_1_s"].description
    assert "[mm]" in flows["lamb_oseen"]["core_radius_mm"].description
    assert "[mm^4/s^2]" in flows["round_jet"]["momentum_flux_mm4_s2"].description
    assert "[rad/s]" in flows["solid_body"]["omega_rad_s"].description


def test_name_is_optional_as_the_loader_defaults_it(tmp_path):
    """An experiment file without ``name`` loads, named after the file; the reference says so
    instead of calling the key required."""
    src = SCENES / "tomo4"
    text = (src / "experiment.toml").read_text()
    assert 'name = "tomo4"\n' in text
    shutil.copytree(src, tmp_path / "tomo4", ignore=shutil.ignore_patterns("*.ply", "*.npz", "*.csv"))
    p = tmp_path / "tomo4" / "my_run.toml"
    p.write_text(text.replace('name = "tomo4"\n', ""))
    assert load_experiment(p).name == "my_run"
    for kind in ("tomo", "backlit", "tracking"):
        row = [ln for ln in describe(get_kind(kind).schema).splitlines() if ln.startswith("| `name` |")]
        assert len(row) == 1 and "| required |" not in row[0], row
