"""The tomo report's choices that need no run: the plane of flow_slice.png
(``[report] slice_axis = "auto"`` and a given axis and position) on fields of known flows,
and the ``[report]`` and ``[particles] threshold_of`` values refused when the experiment
loads. The report of a finished run is checked in tests/studies/test_outputs.py."""

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from mitpiv.errors import ConfigError
from mitpiv.physics.flows import flow_from_dict
from mitpiv.studies import load_experiment
from mitpiv.studies.report import flow_slice_plane

TOMO4 = Path(__file__).resolve().parents[2] / "scenes" / "tomo4" / "experiment.toml"

#: The lattice of a PIV field like the demo's: 0.8 mm apart over a 40 x 40 x 8 mm box.
X = np.arange(-18.4, 18.5, 0.8)
Z = np.arange(-2.4, 2.5, 0.8)


def _field(flow: dict):
    """A PIV field's coordinates and the flow sampled on them, (n_z, n_y, n_x, 3)."""
    zz, yy, xx = np.meshgrid(Z, X, X, indexing="ij")
    pts = np.column_stack([xx.ravel(), yy.ravel(), zz.ravel()])
    ref = flow_from_dict(flow)(pts, 0.0).reshape(zz.shape + (3,))
    return SimpleNamespace(x_mm=X, y_mm=X, z_mm=Z), ref


@pytest.mark.parametrize("flow, axis, by", [
    # a vortex along x / y / z: the plane across its axis shows the swirl (the others: dots)
    ({"kind": "lamb_oseen", "circulation_mm2_s": 1000.0, "core_radius_mm": 2.0, "axis": (1, 0, 0)}, "x", "vorticity"),
    ({"kind": "lamb_oseen", "circulation_mm2_s": 1000.0, "core_radius_mm": 2.0, "axis": (0, 1, 0)}, "y", "vorticity"),
    ({"kind": "lamb_oseen", "circulation_mm2_s": 1000.0, "core_radius_mm": 2.0, "axis": (0, 0, 1)}, "z", "vorticity"),
    # the demo's ring (axis y): the z mid-plane cuts both cores, though the x mid-plane has
    # more in-plane speed (the jet through the ring)
    ({"kind": "vortex_ring", "ring_radius_mm": 8.0, "circulation_mm2_s": 2000.0, "core_radius_mm": 2.0,
      "center": (0.0, -4.0, 0.0), "axis": (0.0, 1.0, 0.0)}, "z", "vorticity"),
    # no vorticity: the largest in-plane speed; ties to z, then y
    ({"kind": "uniform", "velocity_mm_s": (0.0, 0.0, 50.0)}, "y", "speed"),
    ({"kind": "uniform", "velocity_mm_s": (50.0, 0.0, 0.0)}, "z", "speed"),
    ({"kind": "uniform", "velocity_mm_s": (0.0, 50.0, 0.0)}, "z", "speed"),
])
def test_auto_slice_is_the_mid_plane_of_the_most_in_plane_motion(flow, axis, by):
    field, ref = _field(flow)
    p = flow_slice_plane(field, ref, "auto")
    assert (p["axis"], p["by"]) == (axis, by), p
    coords = {"x": X, "y": X, "z": Z}[axis]
    assert p["index"] == coords.size // 2 and p["position_mm"] == coords[coords.size // 2]
    if flow["kind"] == "vortex_ring":
        assert p["mean_in_plane"]["x"] > p["mean_in_plane"]["z"]  # speed alone would pick x
        assert p["mean_vorticity"]["z"] > 5 * p["mean_vorticity"]["x"]


def test_given_slice_axis_takes_the_plane_nearest_its_position():
    field, ref = _field({"kind": "uniform", "velocity_mm_s": (50.0, 0.0, 0.0)})
    p = flow_slice_plane(field, ref, "x", -7.9)
    assert (p["axis"], p["position_mm"], p["by"]) == ("x", pytest.approx(-8.0), None)
    assert X[p["index"]] == p["position_mm"]
    p = flow_slice_plane(field, ref, "z", None)
    assert (p["axis"], p["index"]) == ("z", Z.size // 2)
    p = flow_slice_plane(field, ref, "z", 100.0)  # the outermost plane (the schema refuses this earlier)
    assert p["index"] == Z.size - 1


@pytest.mark.parametrize("overrides, message", [
    ({"report.slice_axis": "w"}, r"\[report\] slice_axis: 'w' is not a valid choice; choose one of 'auto', 'x', "
                                 r"'y' or 'z'"),
    ({"report.slice_mm": 2.0}, r"\[report\]: slice_mm = 2 with slice_axis = 'auto'.*give slice_axis = 'x', 'y' or "
                               r"'z' with slice_mm, or drop slice_mm"),
    ({"report.slice_axis": "z", "report.slice_mm": 9.0}, r"\[report\] slice_mm = 9 mm lies outside the reconstructed "
                                                         r"volume along z \(-4 \.\. 4 mm, \[reconstruction\] "
                                                         r"bounds_mm\); give a position within it"),
    ({"report.slice": "x"}, r"\[report\] slice: unknown key.*Did you mean 'slice_mm'"),
    ({"particles.threshold_of": "median"}, r"\[particles\] threshold_of: 'median' is not a valid choice; choose one "
                                           r"of 'robust' or 'max'"),
])
def test_bad_report_and_threshold_values_are_refused_at_load(overrides, message):
    with pytest.raises(ConfigError, match=message):
        load_experiment(TOMO4, overrides)


def test_report_and_threshold_defaults():
    cfg = load_experiment(TOMO4)
    assert (cfg.report.slice_axis, cfg.report.slice_mm, cfg.particles.threshold_of) == ("auto", None, "robust")
    cfg = load_experiment(TOMO4, {"report.slice_axis": "y", "report.slice_mm": -4.0, "particles.threshold_of": "max"})
    assert (cfg.report.slice_axis, cfg.report.slice_mm, cfg.particles.threshold_of) == ("y", -4.0, "max")
