"""The Mie phase function of a chosen tracer particle: how much light it scatters towards a
camera at each scattering angle, for unpolarised and polarised light, and for a
log-normal size distribution (which smooths the single-size ripples).

    .venv/bin/python examples/mie_phase_function.py --diameter-um 1.0 --index 1.45
    .venv/bin/python examples/mie_phase_function.py --diameter-um 10 --index 1.33   # a water droplet

Writes mie_phase_function.png and prints the scattering efficiency, cross-section and
asymmetry parameter.
"""

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # write PNG files, no window
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from mitpiv.physics import mie  # noqa: E402

cli = argparse.ArgumentParser(description="Mie phase function of a tracer particle")
cli.add_argument("--diameter-um", type=float, default=1.0, help="particle diameter [um] (default: 1 um DEHS)")
cli.add_argument("--index", type=float, default=1.45, help="particle refractive index (DEHS 1.45, water 1.33)")
cli.add_argument("--wavelength-nm", type=float, default=532.0, help="laser wavelength [nm]")
cli.add_argument("--small", action="store_true", help="fewer angles (the test suite's quick run)")
cli.add_argument("--out", default="out/examples/mie_phase_function", help="output folder")
args = cli.parse_args()
out = Path(args.out)
out.mkdir(parents=True, exist_ok=True)

# Scattering angles 0..180 deg (0 = forward, along the laser); fewer in the small run.
theta = np.linspace(0.0, 180.0, 181 if args.small else 721)
d, m, lam = args.diameter_um, args.index, args.wavelength_nm

# Efficiencies and cross-section of one sphere (C_sca = Q_sca * pi d^2 / 4, in mm^2).
e = mie.efficiencies(d, m, wavelength_nm=lam)
print(f"d = {d} um, n = {m}, {lam} nm: size parameter x = {np.pi * d * 1e3 / lam:.2f}, "
      f"Q_sca = {float(e.qsca):.3f}, C_sca = {float(e.csca_mm2):.3e} mm^2, asymmetry g = {float(e.g):.3f}")

# Normalised phase functions [1/sr] (their integral over the sphere is 1).
p = mie.phase_function(d, m, theta, wavelength_nm=lam)
par = mie.phase_function(d, m, theta, wavelength_nm=lam, polarization="parallel")
per = mie.phase_function(d, m, theta, wavelength_nm=lam, polarization="perpendicular")
# A real seeding is polydisperse: a log-normal distribution (geometric std 1.3) of the same median.
p_ln = mie.phase_function(mie.lognormal(d, 1.3, nodes=41 if args.small else 161), m, theta, wavelength_nm=lam)

fig, ax = plt.subplots(figsize=(7.5, 4.5))
ax.semilogy(theta, p, "k", lw=1.5, label="unpolarised")
ax.semilogy(theta, par, "C0", lw=0.8, label="polarised parallel to the scattering plane")
ax.semilogy(theta, per, "C3", lw=0.8, label="polarised perpendicular")
ax.semilogy(theta, p_ln, "C2--", lw=1.2, label="unpolarised, log-normal sizes (sigma_g 1.3)")
for angle in (35.0, 90.0, 145.0):  # typical camera positions: forward, side, back scatter
    ax.axvline(angle, color="0.8", lw=0.8, zorder=0)
ax.set_xlabel("scattering angle [deg] (0 = forward)")
ax.set_ylabel("phase function [1/sr]")
ax.set_title(f"Mie scattering: d = {d} um, n = {m}, {lam:g} nm")
ax.legend(fontsize=8)
ax.grid(True, which="both", alpha=0.2)
fig.tight_layout()
fig.savefig(out / "mie_phase_function.png", dpi=110)
print(f"forward / back scatter (35 / 145 deg): {np.interp(35, theta, p) / np.interp(145, theta, p):.1f}x")
print(f"-> {out / 'mie_phase_function.png'}")
