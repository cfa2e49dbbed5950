"""`mitpiv bench accuracy-time` on its quick preset: every knob the issue names is measured,
errors fall as the knobs converge, the outputs are written, bad input writes nothing."""

import csv

import numpy as np
import pytest

from mitpiv.errors import ConfigError
from mitpiv.studies.accuracy import STAGES, accuracy_time
from mitpiv.studies.shared import pareto_front


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("acc")
    return out, accuracy_time(out, size="quick")


def series(rows, stage, prefix):
    sub = [r for r in rows if r.stage == stage and r.knob.startswith(prefix)]
    assert sub, (stage, prefix)
    return sub


def test_every_knob_is_measured(quick):
    out, rows = quick
    knobs = {(r.stage, r.knob.split(" (")[0]) for r in rows}
    for k in [("render", "camera tracing"), ("render", "particle tracing, PSF jitter"),
              ("render", "particle tracing, FFT PSF"), ("render", "Mie phase table"),
              ("lightfield", "decoder interpolation"), ("lightfield", "focal planes"), ("reconstruct", "MLOS"),
              ("reconstruct", "MART"), ("reconstruct", "SMART"), ("piv", "single pass, window"),
              ("piv", "passes, windows"), ("end_to_end", "fast"), ("end_to_end", "default")]:
        assert k in knobs, k
    assert all(np.isfinite(r.error) and r.error >= 0 and r.seconds > 0 for r in rows)
    with open(out / "accuracy_time.csv") as f:
        assert len(list(csv.DictReader(f))) == len(rows)
    md = (out / "accuracy_time.md").read_text()
    for st in STAGES:
        assert f"## {st}" in md and (out / f"pareto_{st}.png").stat().st_size > 5000


def test_errors_fall_as_knobs_converge(quick):
    _, rows = quick
    # deterministic particle tracing: the phase table and PSF sampling errors fall steadily
    for prefix in ("Mie phase table (tolerance", "Mie phase table (fixed angles", "particle tracing, FFT PSF"):
        e = [r.error for r in series(rows, "render", prefix)]
        assert all(b < a for a, b in zip(e, e[1:], strict=False)), (prefix, e)
    # the default table (tolerance 1e-3 on the phase function at every angle) keeps the image
    # within the tolerance of the 1e-5 reference: an image is a positive mix of phase values
    default = [r for r in series(rows, "render", "Mie phase table (tolerance") if float(r.value) == 1e-3]
    assert len(default) == 1 and default[0].error < 1e-3, default
    # Monte Carlo knobs: error ~ 1/sqrt(samples); 16x the rays gives < 0.45x the error
    jit = [r.error for r in series(rows, "render", "particle tracing, PSF jitter")]
    assert jit[-1] < 0.45 * jit[0]
    cam = [r.error for r in series(rows, "render", "camera tracing")]
    assert cam[-1] < 0.7 * cam[0]
    planes = [r.error for r in series(rows, "lightfield", "focal planes")]
    assert planes[-1] < planes[0]
    piv = {r.value: r.error for r in rows if r.stage == "piv"}
    assert piv["24-16"] < piv["16"]  # the multi-pass predictor beats one pass of the same final window
    q = [1 - r.error for r in rows if r.stage == "reconstruct"]
    assert min(q) > 0.3


def test_pareto_front():
    t = [1.0, 2.0, 3.0, 1.5, 4.0]
    e = [0.5, 0.2, 0.3, 0.6, 0.1]
    assert pareto_front(t, e).tolist() == [True, True, False, False, True]
    assert pareto_front([1.0, 1.0], [0.2, 0.2]).tolist() == [True, True]  # ties are kept


def test_cli_bench_and_bad_input(tmp_path, capsys):
    from mitpiv.cli import main

    assert main(["bench", "accuracy-time", "--quick", "--stages", "piv", "--out", str(tmp_path / "b")]) == 0
    assert (tmp_path / "b" / "pareto_piv.png").is_file()
    assert not (tmp_path / "b" / "pareto_render.png").exists()
    assert main(["bench", "accuracy-time", "--quick", "--stages", "pivot", "--out", str(tmp_path / "c")]) == 2
    assert "pivot" in capsys.readouterr().err and not (tmp_path / "c").exists()
    with pytest.raises(ConfigError, match="size"):
        accuracy_time(tmp_path / "d", size="huge")
