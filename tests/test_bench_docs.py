"""The benchmark pages: generated blocks replace only themselves, the README's performance
table is regenerated from docs/benchmarks.md, and the committed README holds exactly what
the committed benchmarks page regenerates (so neither is edited by hand out of step)."""

import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

import docblocks  # noqa: E402


def test_replace_block_keeps_the_prose_around_it():
    page = "# T\n\nbefore\n\n<!-- begin a -->\nold 1\nold 2\n<!-- end a -->\n\nafter\n"
    new = docblocks.replace_block(page, "a", "new\n")
    assert new == "# T\n\nbefore\n\n<!-- begin a -->\nnew\n<!-- end a -->\n\nafter\n"
    assert docblocks.read_block(new, "a") == "new"
    # a second block is appended under its heading, the first left as it was
    two = docblocks.replace_block(new, "b", "rows", heading="B")
    assert two.startswith(new) and two.endswith("## B\n\n<!-- begin b -->\nrows\n<!-- end b -->\n")
    assert docblocks.read_block(two, "a") == "new" and docblocks.read_block(two, "missing") is None


def test_bad_blocks_are_named():
    with pytest.raises(ValueError, match="'<!-- end a -->'"):
        docblocks.replace_block("<!-- begin a -->\nno end\n", "a", "x")
    with pytest.raises(ValueError, match="block name 'A B'"):
        docblocks.markers("A B")


def test_update_file_is_atomic_and_creates(tmp_path):
    f = tmp_path / "sub" / "page.md"
    docblocks.update_file(f, "x", "one")
    docblocks.update_file(f, "x", "two")
    assert f.read_text() == "<!-- begin x -->\ntwo\n<!-- end x -->\n"
    assert sorted(p.name for p in f.parent.iterdir()) == ["page.md"]


def test_table_rows_reads_the_first_table_only():
    block = "text\n\n| a | b |\n|---|---|\n| 1 | 2 |\n| 3 | 4 |\n\n| c |\n|---|\n| 5 |\n"
    assert docblocks.table_rows(block) == [["1", "2"], ["3", "4"]]
    assert docblocks.table_rows(None) == []


def test_readme_table_regenerated_from_the_page():
    import bench_speed

    page = ("<!-- begin speed-quick -->\n`cmd`. Machine: m, commit abc1234, 2026-01-02 03:04 UTC.\n\n"
            "| stage | ours | baseline | baseline time | ratio | accuracy | notes |\n|---|---|---|---|---|---|---|\n"
            "| MART | 1.00 s | old code | 3.00 s | 3.0x | Q same | n |\n<!-- end speed-quick -->\n"
            "<!-- begin demo -->\n| stage | baseline (b) | ours (h) | ratio | |\n|---|---|---|---|---|\n"
            "| render | 2.0 s | 1.0 s | 2.0x | |\n"
            "| **end to end (`make demo`, wall)** | b: 9.0 s | 3.0 s | 3.0x | metrics: max relative difference 1e-07 |\n"
            "<!-- end demo -->\n")
    out = bench_speed.readme_rows(page)
    assert out.splitlines()[2] == ("| end to end (`make demo`, wall) | 3.0 s | code of b: 9.0 s | 3.0x | "
                                   "metrics: max relative difference 1e-07 |")
    assert out.splitlines()[3] == "| MART | 1.00 s | old code 3.00 s | 3.0x | Q same |"
    assert "(block `speed-quick`, commit abc1234, 2026-01-02)" in out
    with pytest.raises(ValueError, match="no speed-full or speed-quick block"):
        bench_speed.readme_rows("nothing")


def test_committed_readme_matches_the_benchmarks_page():
    import bench_speed

    readme = (ROOT / "README.md").read_text()
    page = (ROOT / "docs" / "benchmarks.md").read_text()
    assert docblocks.read_block(readme, "speed-table") == bench_speed.readme_rows(page).strip("\n"), (
        "README's speed-table block is not what docs/benchmarks.md regenerates: run "
        "`python -c 'import sys; sys.path.insert(0, \"bench\"); import bench_speed; "
        "bench_speed.write_readme_table(\"docs/benchmarks.md\")'`")


def test_demo_metric_difference():
    import bench_demo

    a = {"evaluate": {"frame0": {"Q": 0.5, "bias": [1.0, -2.0]}}, "piv": {"rms_vox": [0.07, 0.06, 0.04]},
         "seconds.total": 9.0, "flag": True}
    b = {"evaluate": {"frame0": {"Q": 0.5, "bias": [1.0, -2.1]}}, "piv": {"rms_vox": [0.07, 0.06, 0.04]},
         "seconds.total": 3.0, "flag": False}
    worst, where, n = bench_demo.metric_diff(a, b)
    assert where == "evaluate.frame0.bias.1" and worst == pytest.approx(0.1 / 2.1, rel=1e-12) and n == 6
    b["piv"]["rms_vox"][2] = float("nan")
    assert bench_demo.metric_diff(a, b)[:2] == (float("inf"), "piv.rms_vox.2")
    assert bench_demo.headline(a) == "Q 0.5000, PIV RMS error 0.0700 / 0.0600 / 0.0400 voxel"
