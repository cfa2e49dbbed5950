"""Atomic writes and run-folder safety: fsync of the file before its rename and of the
folder after it, the free-space check before a large write, byte-deterministic ``.npz``
files, the clean-up of an interrupted run's temporary files, and the folder lock that
names its holder."""

import json
import os
import socket
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from mitpiv.errors import DiskSpaceError, FolderLockedError
from mitpiv.io.arrays import write_npz
from mitpiv.io.atomic import atomic_path, clean_temps, folder_lock

ROOT = Path(__file__).resolve().parents[2]


def test_atomic_path_fsyncs_the_file_before_the_rename_and_the_folder_after(tmp_path, monkeypatch):
    calls = []
    real_fsync, real_replace = os.fsync, os.replace

    def fsync(fd):
        calls.append(("fsync", os.path.realpath(f"/proc/self/fd/{fd}")))
        real_fsync(fd)

    def replace(a, b):
        calls.append(("replace", str(b)))
        real_replace(a, b)

    monkeypatch.setattr(os, "fsync", fsync)
    monkeypatch.setattr(os, "replace", replace)
    with atomic_path(tmp_path / "a.txt") as tmp:
        tmp.write_text("x")
    monkeypatch.undo()
    assert [c[0] for c in calls] == ["fsync", "replace", "fsync"]
    assert calls[0][1] == str(tmp) and calls[1][1] == str(tmp_path / "a.txt") and calls[2][1] == str(tmp_path)


def test_a_large_write_without_the_space_fails_first_and_leaves_nothing(tmp_path, monkeypatch):
    import shutil

    free = 10 * 2**20
    monkeypatch.setattr(shutil, "disk_usage", lambda p: shutil._ntuple_diskusage(2**40, 2**40 - free, free))
    vol = np.zeros((64, 64, 64))  # 2 MiB: fits in 10 MiB free but not with the 64 MiB reserve
    with pytest.raises(DiskSpaceError, match=r"'volume.npz'.*needs about 2\.0 MiB.*10\.0 MiB is free"):
        write_npz(tmp_path / "volume.npz", {"volume": vol})
    assert list(tmp_path.iterdir()) == []
    monkeypatch.undo()
    write_npz(tmp_path / "volume.npz", {"volume": vol})


def test_npz_files_depend_on_their_content_only(tmp_path, monkeypatch):
    """np.savez stamps each entry with the current time; write_npz does not, so a stage's
    output checksum is a function of its arrays."""
    import time

    a = {"x": np.arange(12.0).reshape(3, 4), "meta": '{"a": 1}'}
    write_npz(tmp_path / "a.npz", a)
    t = time.time()
    monkeypatch.setattr(time, "time", lambda: t + 86400 * 400)  # a year later
    write_npz(tmp_path / "b.npz", a)
    monkeypatch.undo()
    assert (tmp_path / "a.npz").read_bytes() == (tmp_path / "b.npz").read_bytes()
    with np.load(tmp_path / "b.npz") as z:
        np.testing.assert_array_equal(z["x"], a["x"])
        assert str(z["meta"]) == a["meta"]


def test_clean_temps_removes_only_temporary_files(tmp_path):
    # only mitpiv's tagged names go: a user's hidden files of any temporary-looking shape
    # (and the untagged names of earlier versions) stay, as do a file of the folder shape,
    # a folder of the file shape and the current holder's own folder
    dirs = ["render", ".render.tmp", ".render.old", ".cache.old", ".piv.mitpiv-tmp-0123456789ab",
            ".piv.mitpiv-old-0123456789ab", ".x.npz.mitpiv-tmp-k2j3h4g5.npz.d", ".evaluate.mitpiv-tmp-ffffffffffff"]
    keep = ["metrics.json", ".mitpiv.lock", ".mitpiv.lock.owner", "render", ".hidden_user_file", ".render.tmp",
            ".render.old", ".cache.old", ".config.settings.json", ".notes.old_2024.txt", ".x.tmp",
            ".metrics.json.tmp-abc123.json", ".volume_0.npz.k2j3h4g5.npz", ".a.mitpiv-tmp-0123456789ab",
            ".x.npz.mitpiv-tmp-k2j3h4g5.npz.d", ".evaluate.mitpiv-tmp-ffffffffffff"]
    drop = [".metrics.json.mitpiv-tmp-abc12_3x.json", ".volume_0.npz.mitpiv-tmp-k2j3h4g5.npz",
            ".piv.mitpiv-tmp-0123456789ab", ".piv.mitpiv-old-0123456789ab"]
    for n in keep + drop:
        if n in dirs:
            (tmp_path / n).mkdir()
            (tmp_path / n / "x.exr").write_text("")
        else:
            (tmp_path / n).write_text("")
    removed = clean_temps(tmp_path, token="ffffffffffff")
    assert sorted(p.name for p in removed) == sorted(drop)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(keep)


def test_temporary_names_carry_the_tag_and_the_lock_token(tmp_path):
    from mitpiv.io.atomic import temp_dir

    with folder_lock(tmp_path) as token:
        assert len(token) == 12 and int(token, 16) >= 0
        with folder_lock(tmp_path) as again:  # a nested hold: the same token
            assert again == token
        assert json.loads((tmp_path / ".mitpiv.lock.owner").read_text())["token"] == token
        assert temp_dir(tmp_path, "render").name == f".render.mitpiv-tmp-{token}"
        assert temp_dir(tmp_path, "render", "old").name == f".render.mitpiv-old-{token}"
        seen = []
        with atomic_path(tmp_path / "a.json") as tmp:
            seen.append(tmp.name)
            tmp.write_text("{}")
        assert seen[0].startswith(".a.json.mitpiv-tmp-") and seen[0].endswith(".json")
    with folder_lock(tmp_path) as other:
        assert other != token  # a new hold: a new token
    with pytest.raises(ValueError, match="inside folder_lock"):
        temp_dir(tmp_path, "render")


def test_a_locked_folder_names_its_holder(tmp_path):
    code = ("import sys, time; from mitpiv.io.atomic import folder_lock\n"
            "with folder_lock(sys.argv[1]):\n    print('held', flush=True); time.sleep(60)\n")
    proc = subprocess.Popen([sys.executable, "-c", code, str(tmp_path)], stdout=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONPATH": str(ROOT)})
    try:
        assert proc.stdout.readline().strip() == "held"
        with pytest.raises(FolderLockedError) as e:
            with folder_lock(tmp_path):
                pass
        msg = str(e.value)
        assert f"is locked by PID {proc.pid} on host {socket.gethostname()} since " in msg
        assert "another output folder" in msg
    finally:
        proc.kill()
        proc.wait()
    # the holder died: the OS released its lock, the folder is free at once
    with folder_lock(tmp_path):
        with folder_lock(tmp_path):  # the same thread may take it again
            pass
        errors = []

        def other():
            try:
                with folder_lock(tmp_path):
                    pass
            except FolderLockedError as err:
                errors.append(str(err))

        t = threading.Thread(target=other)
        t.start()
        t.join()
        assert len(errors) == 1 and f"PID {os.getpid()}" in errors[0]  # another thread of this process is refused too
    with folder_lock(tmp_path):
        pass
