"""The documentation builds with warnings as errors (``make docs``), and its generated pages
hold what they are generated from: the experiment schema of every kind, every example with
its source, the API of the VTK writers."""

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
    assert "ParaView" in (tmp_path / "getting-started.html").read_text()
