"""The ParaView hand-off: every ``DataSet`` of a written ``run.pvd`` names its file relative
to the ``.pvd``'s own folder, which is how PVD readers (ParaView, VTK's vtkPVDReader) find
them, and stays valid after the stage folder's temporary-to-final rename; for every way a run
is exported (the ``[output] vtk = true`` stage, ``mitpiv export RUN --vtk [--out DIR]`` and
:func:`mitpiv.studies.export.export_vtk`), from any working folder and with relative paths."""

import os
import shutil
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from mitpiv.cli import main
from mitpiv.studies import run_experiment
from mitpiv.studies.export import export_vtk

from .helpers import tiny_experiment

try:  # the VTK readers that a PVD reader hands each resolved entry to (optional here)
    import vtk
except ImportError:  # pragma: no cover - vtk is installed with the test extras
    vtk = None

#: The tomo export's collection: 5 parts (volume, particles true / found, piv, true tracks) at 2 frame times.
N_ENTRIES = 10


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """The tiny experiment with ``[output] vtk = true``, run as ``mitpiv run exp.toml --out
    run`` from its own folder (a relative run folder, as a user types it)."""
    d = tmp_path_factory.mktemp("pvd")
    exp = tiny_experiment(d)
    exp.write_text(exp.read_text() + "\n[output]\nvtk = true\n")
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(d)
        run_experiment(Path("exp.toml"), Path("run"))
    return d / "run"


def assert_pvd_resolves(pvd: Path) -> list[str]:
    """Every entry of ``pvd`` is a relative path that names an existing file from the .pvd's
    folder (whatever the working folder is), and that file loads; returns the entries."""
    pvd = Path(pvd).resolve()
    ds = ET.parse(pvd).getroot().findall("./Collection/DataSet")
    files = [e.get("file") for e in ds]
    assert len(files) == N_ENTRIES, files
    absolute = [f for f in files if Path(f).is_absolute()]
    assert not absolute, f"absolute entries in {pvd}: {absolute}"
    missing = [f for f in files if not (pvd.parent / f).is_file()]
    assert not missing, f"{len(missing)} of {len(files)} entries of {pvd} do not resolve from its folder: {missing}"
    # every file lies beside the collection: plain names, valid wherever the folder is moved
    assert all(Path(f).name == f for f in files), files
    if vtk is not None:
        readers = {".vti": vtk.vtkXMLImageDataReader, ".vts": vtk.vtkXMLStructuredGridReader,
                   ".vtu": vtk.vtkXMLUnstructuredGridReader}
        for f in set(files):
            r = readers[Path(f).suffix]()
            r.SetFileName(str(pvd.parent / f))
            r.Update()
            assert r.GetOutput().GetNumberOfPoints() > 0, f
    return files


def test_stage_pvd_resolves_after_the_stage_folder_rename(run):
    vt = run / "vtk"
    assert (vt / "stage.json").is_file()
    assert not [p for p in run.iterdir() if p.name.startswith(".vtk.")]  # the temporary folder is gone
    files = assert_pvd_resolves(vt / "run.pvd")
    assert "volume_0.vti" in files and "tracks_true.vtu" in files


@pytest.mark.parametrize("how", ["cli", "library"])
def test_export_with_relative_out_from_another_folder(run, tmp_path, monkeypatch, how):
    monkeypatch.chdir(tmp_path)
    rel_run = os.path.relpath(run, tmp_path)  # e.g. ../pvd0/run
    if how == "cli":
        assert main(["export", rel_run, "--vtk", "--out", "x/vtk"]) == 0
    else:
        export_vtk(rel_run, "x/vtk")
    assert_pvd_resolves(tmp_path / "x" / "vtk" / "run.pvd")


@pytest.mark.parametrize("how", ["cli", "library"])
def test_export_of_dot_from_inside_the_run(run, tmp_path, monkeypatch, how):
    copy = tmp_path / "run"
    shutil.copytree(run, copy, ignore=shutil.ignore_patterns("vtk", ".mitpiv.lock*"))
    monkeypatch.chdir(copy)
    if how == "cli":
        assert main(["export", ".", "--vtk"]) == 0
    else:
        export_vtk(".")
    assert_pvd_resolves(copy / "vtk" / "run.pvd")
