"""The replication frame: results.json / report.md contract, resumable points, the CLI verb.

A toy study (registered for the test only) computes a closed form so every number it
writes can be checked here: the mean of 1..n against n(n+1)/2/n.
"""

from __future__ import annotations

import json
import sys
import types

import pytest

import mitpiv.replications as replications
from mitpiv.cli import main
from mitpiv.errors import ConfigError
from mitpiv.replications import frame as replication
from mitpiv.replications.frame import (
    RESULTS_KEYS,
    Curve,
    Kind,
    ReplicationResult,
    Row,
    Study,
    classify_rows,
    compare_trend,
    compare_value,
    reclassify,
    replicate,
    tally,
    tally_line,
)

from .helpers import committed_rows

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
            required_ids=("mean_n2", "mean_n4", "rising"),
            kinds={"cached": Kind("info", why="a stored constant, shown for context")})


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
    assert rows["cached"]["kind"] == "info" and rows["mean_n2"]["kind"] == "physics"
    assert rows["mean_n4"]["verdict"] == "disagrees" and rows["mean_n2"]["n"] == 1 and rows["mean_n2"]["ci"] is None
    assert res["tally"]["paper-model"] == {"n": 3, "agree": 2, "disagree": 1, "inconclusive": 0}
    assert res["curves"]["mean"] == {"x": [2, 4], "y": {"ours": [1.5, 2.5]}, "x_label": "n", "y_label": "mean",
                                     "paper": {"paper": [1.5, 2.5]}, "paper_x": [2, 4]}
    md = (tmp_path / "q" / "report.md").read_text()
    assert md.splitlines()[0] == ("**2 of 3 physics rows agree, 1 disagree, 0 inconclusive (arm paper-model)**; "
                                  "not counted: 0 input, 0 definition, 1 info rows")
    assert "| `mean_n4` |" in md and "**no**" in md
    # the info row sits in the table of rows not counted, with its reason
    apart = md.split("## Rows not counted", 1)[1]
    assert "| `cached` | info |" in apart and "a stored constant" in apart and "| `mean_n2` |" not in apart
    assert "![mean.png](mean.png)" in md and (tmp_path / "q" / "mean.png").stat().st_size > 1000
    assert "--quick" in res["command"]
    assert (res["points_computed"], res["points_cached"], res["cached_point_commits"]) == (3, 0, {})
    assert "read back" not in md and res["mixed_commits"] is False


def test_points_resume_from_the_cache(toy, tmp_path):
    replicate("toy", tmp_path / "r", quick=True)
    assert sorted(CALLS) == [2, 4]
    CALLS.clear()
    replicate("toy", tmp_path / "r", quick=False)  # the full scale reuses n=2, n=4 and runs n=8 only
    assert CALLS == [8]
    res = json.loads((tmp_path / "r" / "results.json").read_text())
    assert res["scale"] == "full" and res["curves"]["mean"]["y"]["ours"] == [1.5, 2.5, 4.5]
    # n=8 computed; n=2, n=4 and the "once" value read back: the report says so beside the wall time
    assert (res["points_computed"], res["points_cached"]) == (1, 3)
    assert set(res["cached_point_commits"]) == {"n2", "n4", "once"}
    assert set(res["cached_point_commits"].values()) == {res["commit"]}
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
    assert "2 of 3 physics rows agree, 1 disagree, 0 inconclusive" in capsys.readouterr().out
    (tmp_path / "f").write_text("x")
    assert main(["replicate", "toy", "--out", str(tmp_path / "f")]) == 2
    assert "is a file" in capsys.readouterr().err


def test_map_on_dask_workers_gives_the_same_results(toy, tmp_path):
    from mitpiv.replications.frame import ReplicationContext

    ctx = ReplicationContext(name="toy", out=tmp_path, workers=2)
    got = ctx.map(_point, [2, 4, 8], key=lambda n: f"n{n}")
    assert got == [{"n": 2, "mean": 1.5}, {"n": 4, "mean": 2.5}, {"n": 8, "mean": 4.5}]
    assert sorted(p.name for p in (tmp_path / "work" / "cache").iterdir()) == ["n2.json", "n4.json", "n8.json"]
    stored = json.loads((tmp_path / "work" / "cache" / "n8.json").read_text())
    assert stored["result"] == {"n": 8, "mean": 4.5} and stored["_point"]["key"] == "n8"
    with pytest.raises(ConfigError, match="unique"):
        ctx.map(_point, [2, 2], key=lambda n: "same")


# ------------------------------------------------------------------------------ second edition (points 7-12)
def test_a_point_cached_by_other_code_is_computed_again(toy, tmp_path, monkeypatch):
    replicate("toy", tmp_path / "s", quick=True)
    CALLS.clear()
    replicate("toy", tmp_path / "s", quick=True)
    assert CALLS == []  # same code: read back
    monkeypatch.setattr(replication, "code_hash", lambda module: "0123456789abcdef")
    res = replicate("toy", tmp_path / "s", quick=True)
    assert sorted(CALLS) == [2, 4]  # other code: computed again, never read back
    assert (res["points_computed"], res["points_cached"]) == (3, 0) and res["code_hash"] == "0123456789abcdef"
    # a cache file of the format before code versions is computed again too
    f = tmp_path / "s" / "work" / "cache" / "n2.json"
    f.write_text(json.dumps({"n": 2, "mean": 99.0}))
    CALLS.clear()
    res = replicate("toy", tmp_path / "s", quick=True)
    assert CALLS == [2] and {r["id"]: r["ours"] for r in res["rows"]}["mean_n2"] == 1.5


def test_full_results_that_mix_commits_are_refused(toy, tmp_path, monkeypatch):
    monkeypatch.setattr(replication, "_commit", lambda: "aaaaaaaaaaaa")
    replicate("toy", tmp_path / "m", quick=True)
    monkeypatch.setattr(replication, "_commit", lambda: "bbbbbbbbbbbb")
    with pytest.raises(ConfigError, match=r"aaaaaaaaaaaa.*--allow-mixed"):
        replicate("toy", tmp_path / "m", quick=False)
    # nothing written: the quick run's results are still there
    assert json.loads((tmp_path / "m" / "results.json").read_text())["scale"] == "quick"
    res = replicate("toy", tmp_path / "m", quick=False, allow_mixed=True)
    assert res["mixed_commits"] is True and res["cached_point_commits"]["n2"] == "aaaaaaaaaaaa"
    assert "Mixed code versions" in (tmp_path / "m" / "report.md").read_text()
    # a quick run may mix (it is never committed as the result)
    assert replicate("toy", tmp_path / "m", quick=True)["mixed_commits"] is True


def _rows():
    return [compare_value("a", "a", "s", 1.0, 1.0, rel=0.1), compare_value("b", "b", "s", 1.0, 2.0, rel=0.1),
            compare_value("c", "c", "s", 196, 196, abs=0.5), Row("d", "d", "s", None, 3.0)]


def test_a_physics_row_may_not_read_a_paper_result():
    study = Study(name="t", paper="p", title="t", run=_run, inputs_from_paper={"n_dih": "196 fragments (Sec. VI)"},
                  kinds={"c": Kind("physics", reads=("n_dih",)), "d": Kind("info", why="context")})
    with pytest.raises(ConfigError, match=r"'c' is a physics row but its value reads .*n_dih.*Kind\('input'"):
        classify_rows(study, _rows())
    ok = Study(name="t", paper="p", title="t", run=_run, inputs_from_paper={"n_dih": "196 fragments (Sec. VI)"},
               kinds={"c": Kind("input", why="the paper's count, released", reads=("n_dih",)),
                      "d": Kind("info", why="context")})
    rows = classify_rows(ok, _rows())
    assert [r.kind for r in rows] == ["physics", "physics", "input", "info"]
    # the input row agrees (it echoes the paper) but is not counted
    assert tally(rows) == {"n": 2, "agree": 1, "disagree": 1, "inconclusive": 0}
    for kinds, match in [({"c": Kind("input", why="x", reads=("undeclared",))}, "does not declare"),
                         ({"c": Kind("definition")}, "without a reason"),
                         ({}, "'d' is a physics row but compares nothing")]:
        with pytest.raises(ConfigError, match=match):
            classify_rows(Study(name="t", paper="p", title="t", run=_run, inputs_from_paper={"n_dih": "x"},
                                kinds={"d": Kind("info", why="c"), **kinds} if kinds else {}), _rows())
    # patterns: an exact id wins over a pattern; the first matching pattern otherwise
    st = Study(name="t", paper="p", title="t", run=_run,
               kinds={"*": Kind("info", why="all"), "b": Kind("definition", why="exact")})
    assert [r.kind for r in classify_rows(st, _rows())] == ["info", "definition", "info", "info"]
    with pytest.raises(ConfigError, match="kind 'nonsense'"):
        Kind("nonsense")


def test_the_tally_counts_physics_rows_only():
    rows = [*_rows()[:3], Row("d", "d", "s", None, 3.0, kind="info", why="x"),
            Row("e", "e", "s", 1.0, 1.0, agrees=True, kind="definition", why="x"),
            Row("f", "f", "s", 1.0, 5.0, verdict="inconclusive", arm="physical")]
    assert tally_line(rows) == ("**2 of 3 physics rows agree, 1 disagree, 0 inconclusive (arm paper-model); 0 of 1 "
                                "physics rows agree, 0 disagree, 1 inconclusive (arm physical)**; not counted: "
                                "0 input, 1 definition, 1 info rows")
    assert tally(rows, "physical") == {"n": 1, "agree": 0, "disagree": 0, "inconclusive": 1}


def test_intervals_and_the_three_valued_verdict():
    from scipy import stats

    x = [0.98, 1.03, 1.01, 0.97, 1.02]
    r = compare_value("q", "q", "s", 1.0, x, rel=0.1)
    # Student-t interval of the mean, written afresh
    m, s = sum(x) / 5, (sum((v - sum(x) / 5) ** 2 for v in x) / 4) ** 0.5
    half = stats.t.ppf(0.975, 4) * s / 5**0.5
    assert r.n == 5 and r.ci_method == "t" and r.ours == pytest.approx(m, rel=1e-12)
    assert r.ci == pytest.approx((m - half, m + half), rel=1e-12) and r.verdict == "agrees" and r.agrees is True
    # the interval misses the band: disagrees
    assert compare_value("q", "q", "s", 1.5, x, rel=0.1).verdict == "disagrees"
    # an interval wider than the band that straddles its edge: inconclusive, neither agrees nor disagrees
    wide = [0.6, 1.5, 0.9, 1.4, 0.7]
    r = compare_value("q", "q", "s", 1.2, wide, abs=0.05)
    assert r.verdict == "inconclusive" and r.agrees is None
    # one value is judged as a point, without an interval
    r = compare_value("q", "q", "s", 1.0, 1.05, rel=0.1)
    assert (r.verdict, r.n, r.ci) == ("agrees", 1, None)
    # a trend's statistic per realisation against a one-sided band ('rises': > 0)
    assert compare_trend("t", "t", "s", "rises", "rises", samples=[0.2, 0.3, 0.25], lower=0).verdict == "agrees"
    assert compare_trend("t", "t", "s", "rises", "flat", samples=[0.2, -0.3, 0.05], lower=0).verdict == "inconclusive"
    assert compare_trend("t", "t", "s", "rises", "falls", samples=[-0.2, -0.3, -0.25], lower=0).verdict == "disagrees"
    with pytest.raises(ConfigError, match="not both"):
        compare_trend("t", "t", "s", "rises", "x", True, samples=[1.0, 2.0], lower=0)
    with pytest.raises(ConfigError, match="band"):
        compare_trend("t", "t", "s", "rises", "x", samples=[1.0, 2.0])
    # a bootstrap interval: seeded, so the same samples give the same interval, and it holds the mean
    b1 = compare_value("q", "q", "s", 1.0, x, rel=0.1, ci_method="bootstrap")
    b2 = compare_value("q", "q", "s", 1.0, x, rel=0.1, ci_method="bootstrap")
    assert b1.ci == b2.ci and b1.ci[0] < m < b1.ci[1] and b1.ci_method == "bootstrap"
    # a realisation without a finite value never agrees
    r = compare_value("q", "q", "s", 1.0, [1.0, float("nan"), 1.0], rel=0.1)
    assert r.verdict == "disagrees" and r.ours is None and "1 of 3 realisation(s)" in r.note


def test_a_pooled_statistic_carries_its_interval_from_resampling_the_realisations():
    """pooled_bootstrap: the s.d. of 25 draws of N(0, 0.3) in each of 20 realisations, pooled
    (500 values). The pooled s.d.'s own standard error is 0.3 / sqrt(2 * 499) = 0.0095, so the
    95 % interval should be about 4 of them wide (0.037; accepted 0.02-0.06) and hold 0.3
    within +-3 standard errors of its centre; seeded, so the same data give the same interval.
    Passed as ``ours``, it decides the verdict with that interval."""
    import numpy as np

    from mitpiv.replications.frame import Pooled, pooled_bootstrap

    rng = np.random.default_rng(11)
    groups = [rng.normal(0.0, 0.3, 25) for _ in range(20)]

    def pooled_sd(gs):
        return float(np.std(np.concatenate(gs), ddof=1))

    p = pooled_bootstrap(groups, pooled_sd)
    lo, hi = p.ci
    assert p.n == 20 and p.value == pytest.approx(pooled_sd(groups), rel=1e-12)
    assert 0.02 < hi - lo < 0.06 and lo < p.value < hi and abs(0.5 * (lo + hi) - 0.3) < 3 * 0.0095
    assert pooled_bootstrap(groups, pooled_sd) == p
    # a dict statistic: every key shares the resamples
    both = pooled_bootstrap(groups, lambda gs: {"sd": pooled_sd(gs), "twice": 2 * pooled_sd(gs)})
    assert both["sd"] == p and both["twice"].ci == pytest.approx((2 * lo, 2 * hi), rel=1e-12)
    r = compare_value("sd", "sd", "s", 0.3, p, rel=0.2)
    assert (r.verdict, r.n, r.ci, r.ci_method) == ("agrees", 20, p.ci, "pooled bootstrap")
    assert compare_value("sd", "sd", "s", 0.45, p, rel=0.1).verdict == "disagrees"
    # one realisation: no interval, judged as a point; a non-finite statistic never agrees
    one = pooled_bootstrap(groups[:1], pooled_sd)
    assert one.ci is None and compare_value("sd", "sd", "s", 0.3, one, rel=0.2).ci is None
    r = compare_value("sd", "sd", "s", 0.3, Pooled(float("nan"), None, 20), rel=0.2)
    assert r.verdict == "disagrees" and r.ours is None


def test_the_code_hash_follows_the_modules_a_point_imports(tmp_path, monkeypatch):
    pkg = tmp_path / "mitpiv"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "study.py").write_text("import numpy\nfrom .sub import model\n\ndef f():\n    from mitpiv import helper\n")
    (pkg / "sub" / "model.py").write_text("X = 1\n")
    (pkg / "helper.py").write_text("from mitpiv.studies import replication\n")
    (pkg / "unrelated.py").write_text("Y = 2\n")
    monkeypatch.setattr(replication, "_PKG_ROOT", pkg)
    assert replication.code_modules("mitpiv.study") == ["mitpiv", "mitpiv.helper", "mitpiv.study", "mitpiv.sub",
                                                        "mitpiv.sub.model"]
    h = replication.code_hash("mitpiv.study")
    (pkg / "unrelated.py").write_text("Y = 3\n")
    assert replication.code_hash("mitpiv.study") == h
    (pkg / "sub" / "model.py").write_text("X = 2\n")  # a module the study imports inside a package
    assert replication.code_hash("mitpiv.study") != h


def test_the_real_studies_hash_their_image_models():
    mods = replication.code_modules("mitpiv.replications.sapiv_distortion.study")
    assert {"mitpiv.replications.sapiv_distortion.model", "mitpiv.reconstruct.sapiv", "mitpiv.analysis.quality"} <= set(mods)
    assert "mitpiv.replications.frame" not in mods  # the writer's changes do not invalidate points
    # a study that renders hashes the Mitsuba plugins its renders load by name (importlib), and their imports
    mods = replication.code_modules("mitpiv.replications.multi_plenoptic.study")
    assert {"mitpiv.render.plugins.plenoptic", "mitpiv.render.plugins.distorted_pinhole",
            "mitpiv.render.plugins.mie_phase", "mitpiv.render.plugins.tracer_particles",
            "mitpiv.physics.mie"} <= set(mods)


def test_reclassify_rewrites_earlier_results_without_computing(toy, tmp_path, monkeypatch):
    replicate("toy", tmp_path / "k", quick=True)
    f = tmp_path / "k" / "results.json"
    old = json.loads(f.read_text())
    # an earlier writer's results: no kinds, a report without the section markers
    for r in old["rows"]:
        for k in ("kind", "why", "reads", "verdict", "ci", "n", "ci_method", "arm"):
            r.pop(k)
    f.write_text(json.dumps(old))
    (tmp_path / "k" / "report.md").write_text(
        "# Replication: Toy\n\n- Agreement: 2 of 3\n\n## Paper vs ours\n\n| id |\n|---|\n| `a` |\n\n"
        "## Method\n\nThe mean of 1..n.\n\n## Figures\n\n![mean.png](mean.png)\n")
    monkeypatch.setattr(replication, "_commit", lambda: "cccccccccccc")
    CALLS.clear()
    new_study = Study(name="toy", paper="none.txt", title="Toy study", run=_run, required_ids=TOY.required_ids,
                      kinds={"cached": Kind("info", why="a stored constant"),
                             "mean_n4": Kind("definition", why="arithmetic")})
    monkeypatch.setattr(sys.modules["mitpiv_toy_study"], "STUDY", new_study)
    res = reclassify("toy", tmp_path / "k")
    assert CALLS == []  # nothing computed
    rows = {r["id"]: r for r in res["rows"]}
    assert rows["mean_n4"]["kind"] == "definition" and rows["mean_n4"]["ours"] == 2.5
    assert res["classified_by"] == "cccccccccccc" and res["computed_by"] == old["commit"]
    md = (tmp_path / "k" / "report.md").read_text()
    assert md.startswith("**2 of 2 physics rows agree, 0 disagree, 0 inconclusive (arm paper-model)**")
    assert "The mean of 1..n." in md and "![mean.png](mean.png)" in md and "no point recomputed" in md
    # the new report reclassifies again to the same text (its sections are marked)
    assert reclassify("toy", tmp_path / "k") and (tmp_path / "k" / "report.md").read_text() == md
    stale = Study(name="toy", paper="none.txt", title="t", run=_run, kinds={"gone_*": Kind("info", why="x"),
                                                                            "cached": Kind("info", why="x")})
    monkeypatch.setattr(sys.modules["mitpiv_toy_study"], "STUDY", stale)
    with pytest.raises(ConfigError, match="gone_"):
        reclassify("toy", tmp_path / "k")
    with pytest.raises(ConfigError, match="no results.json"):
        reclassify("toy", tmp_path / "empty")


@pytest.mark.parametrize("name", ["channel-tomo", "drop-fragments", "lfpiv-vs-tomo", "multi-plenoptic",
                                  "sapiv-distortion"])
def test_the_committed_results_carry_the_studies_kinds_and_the_generated_tally(name):
    from pathlib import Path

    from mitpiv.replications.frame import KINDS, get_study

    folder = Path(__file__).resolve().parents[2] / "docs" / "replications" / name
    d = json.loads((folder / "results.json").read_text())
    assert d["study"] == name and all(r["kind"] in KINDS for r in d["rows"])
    rows = committed_rows(name, declared=True)
    # the committed kinds are the study's declarations today (rows made afresh from the numbers alone)
    study = get_study(name)
    bare = committed_rows(name)
    assert [(r.kind, r.why, r.reads) for r in classify_rows(study, bare)] == [(r.kind, r.why, r.reads) for r in rows]
    assert not replication.unused_kinds(study, rows)
    assert not [r.id for r in rows if r.kind == "physics" and (r.reads or r.verdict == "not compared")]
    md = (folder / "report.md").read_text()
    assert md.splitlines()[0] == tally_line(rows)
    assert d["tally"]["paper-model"] == tally(rows, "paper-model")
    # every row's note and every non-physics row's reason is in the report, pass or fail
    for r in rows:
        for text in (r.note, r.why):
            if text:
                assert text.replace("|", "\\|").replace("\n", " ") in md, (r.id, text[:60])
