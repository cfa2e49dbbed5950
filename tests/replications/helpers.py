"""What every replication test checks of a run's results."""

from __future__ import annotations

from pathlib import Path


def assert_second_edition(res: dict, out: Path) -> None:
    """A replication's results carry the second edition's fields (REPLICATION.md, points 7-12):
    every row a kind, a verdict and its realisations; the points with their code version; and
    the report opens with the physics rows' tally, which counts nothing else."""
    from mitpiv.replications.frame import ARMS, KINDS, VERDICTS

    rows = res["rows"]
    assert rows and all(r["kind"] in KINDS and r["verdict"] in VERDICTS and r["arm"] in ARMS for r in rows)
    assert all(r["n"] >= 1 and (r["ci"] is None or r["ci"][0] <= r["ci"][1]) for r in rows)
    phys_all = [r for r in rows if r["kind"] == "physics"]
    assert not [r["id"] for r in phys_all if r["verdict"] == "not compared" or r["reads"]]
    assert len(res["code_hash"]) == 16 and res["points_computed"] + res["points_cached"] > 0
    for arm in {r["arm"] for r in phys_all} - {"paper-model"}:  # each other arm has its own tally
        own = [r for r in phys_all if r["arm"] == arm]
        assert res["tally"][arm]["n"] == len(own)
    phys = [r for r in phys_all if r["arm"] == "paper-model"]
    t = res["tally"]["paper-model"]
    assert t["n"] == len(phys) and t["agree"] == sum(r["verdict"] == "agrees" for r in phys)
    first = (out / "report.md").read_text().splitlines()[0]
    assert first.startswith(f"**{t['agree']} of {t['n']} physics rows agree, {t['disagree']} disagree, "
                            f"{t['inconclusive']} inconclusive (arm paper-model)")


def committed_rows(name: str, *, declared: bool = False) -> list:
    """The rows of the committed full run ``docs/replications/NAME/results.json``: as written
    (``declared=True``), or without their kind, why and reads, which the study's declarations
    give again (:func:`mitpiv.replications.frame.classify_rows`)."""
    import json

    from mitpiv.replications.frame import Row

    f = Path(__file__).resolve().parents[2] / "docs" / "replications" / name / "results.json"
    drop = () if declared else ("kind", "why", "reads")
    return [Row.from_dict({k: v for k, v in r.items() if k not in drop})
            for r in json.loads(f.read_text(encoding="utf-8"))["rows"]]
