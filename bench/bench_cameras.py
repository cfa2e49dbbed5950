"""Camera cost: distorted_pinhole with effects off / on against Mitsuba's perspective.

Camera tracing (`direct` integrator) of the tomo4-like particle field at 512x512, 16 spp;
each configuration is rendered 5 times after a warm-up, the median is reported with its
ratio to `perspective` measured in the same run.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import mitsuba as mi
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import mitpiv  # noqa: E402,F401
from mitpiv.physics.seeding import seed_box  # noqa: E402
from tests.render.helpers import camera, scene  # noqa: E402


def timed(sc, spp):
    mi.render(sc, spp=spp)  # warm-up: kernel compilation
    t = []
    for k in range(5):
        t0 = time.perf_counter()
        img = mi.render(sc, spp=spp, seed=k + 1)
        np.array(img)
        t.append(time.perf_counter() - t0)
    return float(np.median(t))


def main():
    from mitpiv.render.variant import ensure_variant

    ensure_variant()  # Mitsuba objects below (importing mitpiv selects no variant)
    tmp = Path(tempfile.mkdtemp())
    cam = camera(res=(512, 512))
    pts = seed_box((-14, -14, -3), (14, 14, 3), count=20000, seed=0).positions_mm
    configs = [
        ("perspective (baseline)", "perspective", {}),
        ("distorted_pinhole, effects off", "distorted_pinhole", {}),
        ("distorted_pinhole, 1 % distortion", "distorted_pinhole", {"distortion_percent": 1.0}),
        ("distorted_pinhole, f/8 thin lens", "distorted_pinhole", {"f_number": 8.0, "focus_distance_mm": 500.0}),
    ]
    base = None
    print(f"{'configuration':40s} {'time [s]':>9s} {'ratio':>7s}")
    for name, sensor, props in configs:
        sc = scene(tmp, pts, cam=cam, sensor=sensor, sensor_props=props, integrator={"type": "direct"}, proxy=0.005)
        t = timed(sc, 16)
        base = base or t
        print(f"{name:40s} {t:9.3f} {t / base:7.2f}", flush=True)
    sc = scene(tmp, pts, cam=cam, integrator={"type": "particle_tracer"}, proxy=0.005)
    t = timed(sc, 1)
    print(f"{'particle_tracer, pinhole':40s} {t:9.3f} {t / base:7.2f}")


if __name__ == "__main__":
    main()
