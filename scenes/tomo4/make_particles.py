"""Particles for the tomo4 scene: a seeded box advected by a vortex ring between two frames.

Writes particles_0.ply, particles_1.ply (Mitsuba ellipsoidsmesh input) and truth.npz /
truth.csv (positions of both frames, displacements, diameters, the flow) beside this file.
Run: python scenes/tomo4/make_particles.py [--count N] [--seed S]
"""

from __future__ import annotations

import argparse
from pathlib import Path

from mitpiv.io import write_particles_ply, write_truth
from mitpiv.physics.advection import advect
from mitpiv.physics.flows import VortexRing
from mitpiv.physics.seeding import seed_box

HERE = Path(__file__).resolve().parent
BOX_MIN, BOX_MAX = (-20.0, -20.0, -4.0), (20.0, 20.0, 4.0)  # mm; sheet normal is z
DT_S = 0.002
PROXY_RADIUS_MM = 0.02  # ~0.25 of the 0.08 mm pixel footprint


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--count", type=int, default=12000, help="number of particles (default 12000)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=HERE)
    a = ap.parse_args(argv)
    particles = seed_box(BOX_MIN, BOX_MAX, count=a.count, diameter_um=1.0, distribution="lognormal",
                         geometric_std=1.3, min_separation_mm=0.05, seed=a.seed)
    ring = VortexRing(ring_radius_mm=8.0, circulation_mm2_s=2000.0, core_radius_mm=2.0,
                      center=(0.0, -4.0, 0.0), axis=(0.0, 1.0, 0.0))
    p1 = advect(particles.positions_mm, ring, dt_s=DT_S, t0_s=0.0, substeps=8)
    for k, p in enumerate((particles.positions_mm, p1)):
        write_particles_ply(a.out / f"particles_{k}.ply", p, particles.diameters_um, proxy_radius_mm=PROXY_RADIUS_MM)
    for name in ("truth.npz", "truth.csv"):
        write_truth(a.out / name, positions_mm=[particles.positions_mm, p1], times_s=[0.0, DT_S],
                    diameters_um=particles.diameters_um, flow=ring.to_dict(),
                    extra={"box_min_mm": BOX_MIN, "box_max_mm": BOX_MAX, "seed": a.seed})
    print(f"wrote {len(particles)} particles for frames 0 and 1 to {a.out}")


if __name__ == "__main__":
    main()
