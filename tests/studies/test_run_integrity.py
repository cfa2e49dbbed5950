"""Run folders a user can trust after edits and damage: content-keyed stages (an edited
scene file, a changed setting, a new code version rerun exactly the stages they reach; a
touched but unchanged file reruns nothing), completion records that list every output
with its checksum (a missing or corrupt output reruns its stage), and the scene files that
a render stage's key covers."""

import json
import logging
import re
import shutil
from pathlib import Path
from types import SimpleNamespace

from mitpiv.studies import run_experiment

from .helpers import SCENE, tiny_experiment

STAGES = ("particles", "render", "reconstruct", "evaluate", "piv", "report")


def ran(caplog) -> list[str]:
    """The stages that ran (not skipped) in the logged run."""
    return [s for s in STAGES if re.search(rf"\] {s} \.\.\.", caplog.text)]


def resume(exp, run, caplog, until="piv", **kw):
    """Run (or resume) up to ``until`` (default: all but the report, whose figures would
    only cost time here); returns the per-stage results and the stages that ran."""
    caplog.clear()
    with caplog.at_level(logging.INFO, logger="mitpiv"):
        r = run_experiment(exp, run, until=until, **kw)
    return r.stages, ran(caplog)


def test_edit_then_resume_reruns_exactly_the_affected_stages(tmp_path, caplog, monkeypatch):
    xml = tmp_path / "scene.xml"
    shutil.copy(SCENE, xml)
    exp = tiny_experiment(tmp_path, xml=xml)
    run = tmp_path / "run"
    m0, stages = resume(exp, run, caplog, until=None)
    assert stages == list(STAGES) and (run / "metrics.json").is_file()
    # the scene file rewritten with the same content (new mtime): nothing reruns
    xml.write_bytes(xml.read_bytes())
    assert resume(exp, run, caplog)[1] == []
    # cam0's focal length 85 -> 50 mm in the scene file: the render and every later stage
    # rerun (here first the render alone, then the rest); the particles (which do not read
    # the scene) are kept
    text = xml.read_text()
    cam0 = text.index('id="cam0"')
    edited = text[:cam0] + text[cam0:].replace('name="focal_length_mm" value="85"',
                                               'name="focal_length_mm" value="50"', 1)
    assert edited != text
    xml.write_text(edited)
    assert resume(exp, run, caplog, until="render")[1] == ["render"]
    assert not (run / "metrics.json").exists()  # the earlier run's summary no longer holds
    m1, stages = resume(exp, run, caplog)
    assert stages == ["reconstruct", "evaluate", "piv"]
    assert 'value="50"' in (run / "render" / "scene.xml").read_text()
    assert m1["evaluate"] != m0["evaluate"]  # a fresh run's numbers, not the old ones
    # only a PIV setting: only piv
    assert resume(exp, run, caplog, overrides={"piv.overlap": 0.25})[1] == ["piv"]
    # a corrupt output (one byte changed): its stage reruns; the reconstruction gives the
    # same bytes again, so the stages after it (keyed on its outputs' checksums) are kept
    ov = {"piv.overlap": 0.25}
    f = run / "reconstruct" / "volume_0.npz"
    b = bytearray(f.read_bytes())
    b[len(b) // 2] ^= 0xFF
    f.write_bytes(bytes(b))
    assert resume(exp, run, caplog, overrides=ov)[1] == ["reconstruct"]
    assert "volume_0.npz is changed or corrupt" in caplog.text
    # a missing output: its stage reruns
    (run / "evaluate" / "matches_1.npz").unlink()
    assert resume(exp, run, caplog, overrides=ov)[1][0] == "evaluate"
    assert "matches_1.npz is missing" in caplog.text
    # a record without its outputs list (a stage folder of an older run): the stage reruns
    rec = json.loads((run / "particles" / "stage.json").read_text())
    del rec["outputs"]
    (run / "particles" / "stage.json").write_text(json.dumps(rec))
    assert resume(exp, run, caplog, overrides=ov)[1][0] == "particles"
    # another Mitsuba version: the render and every later stage rerun, not the particles
    import mitpiv.studies.runner as runner

    real = runner.package_version
    monkeypatch.setattr(runner, "package_version", lambda n: "0.0-other" if n == "mitsuba" else real(n))
    assert resume(exp, run, caplog, overrides=ov)[1] == ["render", "reconstruct", "evaluate", "piv"]
    # another mitpiv version: every stage reruns
    monkeypatch.setattr("mitpiv.version.__version__", "0.0-other")
    assert resume(exp, run, caplog, overrides=ov)[1] == list(STAGES[:-1])


def test_render_key_covers_the_files_the_scene_names(tmp_path):
    """scene_files: the XML and every file it names ($name substituted per frame, relative
    names against its folder); the particle files that the run makes are not inputs."""
    from mitpiv.studies.shared import scene_files

    xml = tmp_path / "s.xml"
    xml.write_text("""<scene version="3.0.0">
    <default name="mesh" value="a"/>
    <include filename="common.xml"/>
    <shape type="obj"><string name="filename" value="$mesh_$frame.obj"/></shape>
    <shape type="ellipsoidsmesh"><string name="filename" value="particles_$frame.ply"/></shape>
    <texture type="bitmap"><string name="filename" value="/abs/tex.exr"/></texture>
</scene>""")
    cfg = SimpleNamespace(scene=SimpleNamespace(xml=str(xml), params={"mesh": "b"}))
    assert scene_files(cfg) == [xml, tmp_path / "common.xml", tmp_path / "b_0.obj", tmp_path / "b_1.obj",
                                Path("/abs/tex.exr")]
