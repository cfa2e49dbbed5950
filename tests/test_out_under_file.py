"""An output folder given below a regular file (``--out f/sub`` where ``f`` is a file) is one
clear, early error in every command that writes a folder: exit status 2, one line naming
the flag, its value, the file that is in the way and the fix; raised before any work (the
command's work functions are replaced by ones that fail the test if called), and nothing
is written."""

from __future__ import annotations

import pytest

from mitpiv.cli import main


def _no_work(*a, **k):
    raise AssertionError("the command started its work before checking --out")


@pytest.fixture
def no_work(monkeypatch):
    import mitpiv
    import mitpiv.imaging
    import mitpiv.studies
    import mitpiv.studies.accuracy
    import mitpiv.studies.export

    monkeypatch.setattr(mitpiv, "render_scene", _no_work)
    monkeypatch.setattr(mitpiv.imaging, "apply_sensor_set", _no_work)
    monkeypatch.setattr(mitpiv.studies, "run_experiment", _no_work)
    monkeypatch.setattr(mitpiv.studies, "run_sweep", _no_work)
    monkeypatch.setattr(mitpiv.studies.export, "export_vtk", _no_work)
    monkeypatch.setattr(mitpiv.studies.export, "export_tracker_inputs", _no_work)
    monkeypatch.setattr(mitpiv.studies.accuracy, "accuracy_time", _no_work)


# (command before --out, the flag, the folder below the file)
COMMANDS = [
    ("sensor {img} --peak-photons 100", "--out", "f/sub"),
    ("render {scene}", "--out", "f/sub"),
    ("run {toml}", "--out", "f/sub/run"),
    ("sweep {toml}", "--out", "f/sub"),
    ("export {run} --vtk", "--out", "f/sub"),
    ("export {run} --vtk --out {run}/vtk", "--openlpt", "f/sub"),
    ("export {run}", "--openptv", "f/sub"),
    ("bench accuracy-time --quick", "--out", "f/sub"),
]


@pytest.mark.parametrize(("cmd", "flag", "below"), COMMANDS, ids=[c[0].split()[0] + "-" + c[1][2:] for c in COMMANDS])
def test_out_below_a_file_is_one_early_clear_error(cmd, flag, below, tmp_path, capsys, no_work):
    f = tmp_path / "f"
    f.write_text("a user's file\n")
    (tmp_path / "img.exr").write_bytes(b"")  # never read: --out is checked first
    (tmp_path / "scene.xml").write_text("<scene/>")
    (tmp_path / "exp.toml").write_text('name = "x"\n')
    (tmp_path / "run").mkdir()
    names = {"img": tmp_path / "img.exr", "scene": tmp_path / "scene.xml", "toml": tmp_path / "exp.toml",
             "run": tmp_path / "run"}
    value = str(tmp_path / below)
    argv = cmd.format(**names).split() + [flag, value]
    before = sorted(tmp_path.rglob("*"))
    rc = main(argv)
    err = capsys.readouterr().err
    assert rc == 2, err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("mitpiv: error:") and "Traceback" not in err, err
    assert f"{flag} {value!r}" in err, err  # the flag and its value
    assert f"{str(f)!r} is a file" in err, err  # what is in the way
    assert "another folder" in err or "move" in err, err  # the fix
    assert sorted(tmp_path.rglob("*")) == before
    assert f.read_text() == "a user's file\n"


def test_a_run_folder_below_a_file_is_a_config_error(tmp_path):
    """The library too: run_stages into a folder below a file names it (no NotADirectoryError)."""
    from pydantic import BaseModel

    from mitpiv.errors import ConfigError
    from mitpiv.studies.runner import run_stages

    class Cfg(BaseModel):
        name: str = "x"

    (tmp_path / "f").write_text("")
    with pytest.raises(ConfigError, match=r"is a file"):
        run_stages(Cfg(), tmp_path / "f" / "run", [])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f"]
