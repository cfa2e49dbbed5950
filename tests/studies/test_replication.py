"""The replication frame: results.json / report.md contract, resumable points, the CLI verb.

A toy study (registered for the test only) computes a closed form so every number it
writes can be checked here: the mean of 1..n against n(n+1)/2/n.
"""

from __future__ import annotations

import json
import sys
import types

import pytest

from mitpiv.cli import main
from mitpiv.errors import ConfigError
from mitpiv.studies import replications
from mitpiv.studies.replication import (
    RESULTS_KEYS,
    Curve,
    ReplicationResult,
    Row,
    Study,
    compare_trend,
    compare_value,
    replicate,
)

CALLS: list[int] = []


def _point(n: int) -> dict:
    CALLS.append(n)
    return {"n": n, "mean": sum(range(1, n + 1)) / n}


def _run(ctx):
    ns = [2, 4] if ctx.quick else [2, 4, 8]
    pts = ctx.map(_point, ns, key=lambda n: f"n{n}")
    once = ctx.cached("once", lambda: {"value": 1.5})
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots()
    ax.plot(ns, [p["mean"] for p in pts])
    ax.set_xlabel("n")
    fig_name = ctx.figure(fig, "mean.png")
    rows = [compare_value("mean_n2", "mean of 1..2", "eq. 1", 1.5, pts[0]["mean"], rel=1e-12),
            compare_value("mean_n4", "mean of 1..4", "eq. 1", 2.6, pts[1]["mean"], abs=0.05, why="a wrong paper value"),
            compare_trend("rising", "mean rises with n", "Fig. 1", "rising", "rising",
                          all(a["mean"] < b["mean"] for a, b in zip(pts, pts[1:], strict=False))),
            Row(id="cached", quantity="cached value", paper_source="–", paper=None, ours=once["value"])]
    return ReplicationResult(rows=rows, curves={"mean": Curve(x=ns, y={"ours": [p["mean"] for p in pts]},
                                                              x_label="n", y_label="mean",
                                                              paper={"paper": [1.5, 2.5]}, paper_x=[2, 4])},
                             sections=["## Method\n\nThe mean of 1..n."], figures=[fig_name])


TOY = Study(name="toy", paper="none.txt", title="Toy study", run=_run,
            required_ids=("mean_n2", "mean_n4", "rising"))


@pytest.fixture
def toy(monkeypatch):
    mod = types.ModuleType("mitpiv_toy_study")
    mod.STUDY = TOY
    monkeypatch.setitem(sys.modules, "mitpiv_toy_study", mod)
    monkeypatch.setitem(replications.MODULES, "toy", "mitpiv_toy_study")
    CALLS.clear()
    return TOY


def test_results_and_report_follow_the_contract(toy, tmp_path):
    res = replicate("toy", tmp_path / "q", quick=True)
    on_disk = json.loads((tmp_path / "q" / "results.json").read_text())
    assert on_disk == res
    assert set(RESULTS_KEYS) <= set(res)
    assert res["scale"] == "quick" and res["study"] == "toy"
    rows = {r["id"]: r for r in res["rows"]}
    assert rows["mean_n2"]["agrees"] is True and rows["mean_n2"]["ours"] == 1.5
    # 2.5 vs 2.6 with an absolute tolerance of 0.05: a disagreement, recorded as one
    assert rows["mean_n4"]["agrees"] is False and rows["mean_n4"]["ours"] == 2.5
    assert "±0.05" in rows["mean_n4"]["tolerance"] and "a wrong paper value" in rows["mean_n4"]["tolerance"]
    assert rows["rising"]["agrees"] is True and rows["cached"]["agrees"] is None
    assert res["curves"]["mean"] == {"x": [2, 4], "y": {"ours": [1.5, 2.5]}, "x_label": "n", "y_label": "mean",
                                     "paper": {"paper": [1.5, 2.5]}, "paper_x": [2, 4]}
    md = (tmp_path / "q" / "report.md").read_text()
    assert "| `mean_n4` |" in md and "**no**" in md and "2 of 3 compared rows agree" in md
    assert "![mean.png](mean.png)" in md and (tmp_path / "q" / "mean.png").stat().st_size > 1000
    assert "--quick" in res["command"]
    assert res["points"] == {"computed": 3, "from_cache": 0} and "read back" not in md


def test_points_resume_from_the_cache(toy, tmp_path):
    replicate("toy", tmp_path / "r", quick=True)
    assert sorted(CALLS) == [2, 4]
    CALLS.clear()
    replicate("toy", tmp_path / "r", quick=False)  # the full scale reuses n=2, n=4 and runs n=8 only
    assert CALLS == [8]
    res = json.loads((tmp_path / "r" / "results.json").read_text())
    assert res["scale"] == "full" and res["curves"]["mean"]["y"]["ours"] == [1.5, 2.5, 4.5]
    # n=8 computed; n=2, n=4 and the "once" value read back: the report says so beside the wall time
    assert res["points"] == {"computed": 1, "from_cache": 3}
    assert "1 points computed by this run, 3 read back" in (tmp_path / "r" / "report.md").read_text()


def test_contract_violations_are_refused(toy, tmp_path, monkeypatch):
    bad = Study(name="toy", paper="none.txt", title="t", run=_run, required_ids=("mean_n2", "absent_id"))
    monkeypatch.setattr(sys.modules["mitpiv_toy_study"], "STUDY", bad)
    with pytest.raises(ConfigError, match="absent_id"):
        replicate("toy", tmp_path / "x", quick=True)
    assert not (tmp_path / "x" / "results.json").exists()
    with pytest.raises(ConfigError, match="tolerance"):
        compare_value("a", "a", "s", 1.0, 1.0)
    nan_row = compare_value("a", "a", "s", 1.0, float("nan"), rel=0.1)
    assert nan_row.agrees is False and nan_row.ours is None


def test_cli_names_unknown_studies_and_lists(toy, tmp_path, capsys):
    assert main(["replicate", "toi", "--quick", "--out", str(tmp_path / "c")]) == 2
    err = capsys.readouterr().err
    assert "no study named 'toi'" in err and "Did you mean 'toy'" in err
    assert main(["replicate", "--list"]) == 0
    assert "toy" in capsys.readouterr().out
    assert main(["-q", "replicate", "toy", "--quick", "--out", str(tmp_path / "c")]) == 0
    assert "2/3 rows agree" in capsys.readouterr().out
    (tmp_path / "f").write_text("x")
    assert main(["replicate", "toy", "--out", str(tmp_path / "f")]) == 2
    assert "is a file" in capsys.readouterr().err


def test_map_on_dask_workers_gives_the_same_results(toy, tmp_path):
    from mitpiv.studies.replication import ReplicationContext

    ctx = ReplicationContext(name="toy", out=tmp_path, workers=2)
    got = ctx.map(_point, [2, 4, 8], key=lambda n: f"n{n}")
    assert got == [{"n": 2, "mean": 1.5}, {"n": 4, "mean": 2.5}, {"n": 8, "mean": 4.5}]
    assert sorted(p.name for p in (tmp_path / "work" / "cache").iterdir()) == ["n2.json", "n4.json", "n8.json"]
    with pytest.raises(ConfigError, match="unique"):
        ctx.map(_point, [2, 2], key=lambda n: "same")
