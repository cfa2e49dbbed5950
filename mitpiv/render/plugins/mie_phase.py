"""``mie``: Mie phase function of spheres, tabulated at construction.

Parameters
----------
diameter_um : float [um], required outside ``tracer_particles``, range > 0
    Sphere diameter; with ``geometric_std`` the median of a log-normal distribution.
geometric_std : float, default monodisperse, range > 1
    Geometric standard deviation (> 1) of a log-normal size distribution.
diameters_um, weights : string [um, --]
    A discrete size distribution: comma-separated diameters and number weights.
index : float, default 1.45, range > 0
    Real part n of the particle index n + ik.
index_imag : float, default 0, range >= 0
    Absorption k >= 0 of the particle index n + ik.
medium_index : float, default 1.0, range > 0
    Real index of the surrounding medium (1.333 for water).
wavelength_nm : float [nm]; default 532, or the laser's; range > 0
    Vacuum wavelength. Nested in ``tracer_particles`` it defaults to the laser
    sheet's and must agree with it.
tolerance : float, default 1e-3, range 1e-6 to 0.1
    Relative tolerance of the table: its nodes in the scattering angle are chosen so
    that the interpolated phase function (parallel, perpendicular and unpolarised, as
    ``tracer_particles`` and this plugin evaluate them) is within ``tolerance`` of Mie
    theory at every angle, the deep minima included (range 1e-6 to 0.1; see Notes).
angles : integer, default none (chosen for ``tolerance``), range 16 to 4194304
    A fixed table resolution instead (16 to 4194304 nodes in the scattering angle; half
    of them in the forward peak for large particles, see
    :func:`mitpiv.physics.mie.angle_grid`). Not with ``tolerance``.
size_step : float, default 0.02, range > 0
    Nested in ``tracer_particles`` with per-particle diameters: spacing, in size
    parameter x, of the diameters tabulated for the per-particle lookup (linear
    interpolation between them).

Notes
-----
Accuracy. The table is interpolated linearly in the scattering angle theta. By default
its nodes are chosen for the particle sizes the scene renders
(:func:`mitpiv.physics.mie.phase_table`): 8 per ripple period pi/x, then every interval
whose interpolation error at its midpoint exceeds half the tolerance is halved, so the
nodes crowd towards the deep minima. The stated tolerance, relative at every angle,

    ``|p_table(theta) - p(theta)| <= tolerance (p(theta) + 1e-10 max p)``

holds for one diameter and for a distribution (``geometric_std``, ``diameters_um``),
for ``p_par``, ``p_per`` and their mean (the absolute floor, 1e-10 of the forward peak,
only matters at exact zeros such as a dipole's parallel intensity at 90 deg). Measured
against Mie theory on 300,000 angles and at every minimum (DEHS, n = 1.45, in air,
532 nm; ``bench/bench_mie.py``, 2-core CPU), with the former default of 1024 fixed
angles beside it:

========  =====  =====  ===============  ==========  ===============  ==========
diameter  x      nodes  max rel. error   build [ms]  1024: max error  build [ms]
========  =====  =====  ===============  ==========  ===============  ==========
1 um      5.9    926    4.9e-4           4           9.5e-2           1
5 um      29.5   4154   5.3e-4           12          9.6              2
20 um     118    13810  5.2e-4           83          165              6
========  =====  =====  ===============  ==========  ===============  ==========

Render time does not change measurably (particle tracing of 200k particles and camera
tracing at 16 spp: 0.8-1.1 times the former default's, within the run-to-run noise). The
interval lookup per ray hardly depends on the node count: a uniform grid of 4-16 cells per
node gives an angle's first candidate interval, then a few fixed binary-search steps (2-3
for 1-20 um droplets) finish it (:func:`interval`; 20 um: 7 ns per lookup instead of 19
for a binary search over all 13810 nodes, ``bench/bench_mie.py`` section 6). The node
count grows as ``x / sqrt(tolerance)``
(:func:`mitpiv.physics.mie.adaptive_angles_estimate`; x = 1000: 116,000 nodes in 4 s); a
table whose estimated memory or build time exceeds 4 GiB or 300 s (x = 1e4 at the default
tolerance) is refused before it is built, with the estimate
and the fix (loosen ``tolerance``, or give ``angles``). The ``describe()`` metadata
records the nodes, the tolerance and the measured ``max_error``.

Float32 kernels compute the angle to about 1e-7 rad, a relative error of up to
1e-7 / w on the flank of a minimum of width w (w >= 1.4e-4 rad for the 20 um droplet).

Per-particle diameters (a particle file with several diameters, ``size_step``): the table
takes the grid of its largest diameter, whose ripple is the finest; its other rows are
resolved to the tolerance away from their own deep minima, where (as between rows) the
diameter spacing sets the error. The image of 20k log-normal 1 um particles is within
3e-5 (relative L1) of a 65536-angle table and within 1.6e-4 of a ``size_step`` 0.001 one.

Sampling. The table holds ``2 pi sin(theta) p(theta)`` at its nodes, interpolated
linearly in theta; ``eval``, ``pdf`` and ``sample`` (inverse CDF, exact for the
interpolant) are therefore consistent. Angles are computed as
``2 atan2(|wo + wi|, |wo - wi|)``, accurate in float32 down to the 1/x-wide forward
peak of large spheres (cos(theta) would round to 1 there). Usable as the phase function of
a Mitsuba medium (``volpath``) and nested in ``tracer_particles``, which then also takes the
scattering cross-section and, for a polarised laser sheet, the polarised intensities from
Mie theory.

.. code-block:: xml

    <phase type="mie">
        <float name="diameter_um" value="1"/>
        <float name="index" value="1.45"/>
        <float name="medium_index" value="1.0"/>
        <float name="tolerance" value="1e-3"/>  <!-- the default -->
    </phase>
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from mitpiv.errors import ConfigError, check_positive
from mitpiv.physics import mie
from mitpiv.render.plugins._props import PropertyReader

_VARIANT = mi.variant()


def _floats(text: str, name: str) -> list[float]:
    try:
        return [float(t) for t in text.replace(",", " ").split()]
    except ValueError:
        raise ConfigError(f"mie: '{name}' must be a comma-separated list of numbers, got {text!r}.") from None


def scattering_angle(w_a, w_b):
    """Angle between unit vectors, accurate at 0 and pi in float32: 2 atan2(|a - b|, |a + b|)."""
    return 2.0 * dr.atan2(dr.norm(w_a - w_b), dr.norm(w_a + w_b))


class AngleNodes:
    """Ascending float32 table nodes with a uniform acceleration grid for :func:`interval`.

    Built once, when a table is uploaded. ``cells`` (G) equal cells split
    ``[nodes[0], nodes[-1]]``: the smallest power of two of at least 4 cells per node,
    doubled (up to 16 per node and ``MAX_CELLS``) while that saves a search step; a
    float32 angle's cell is ``(theta - nodes[0]) * scale`` truncated and clamped to
    [0, G-1] (NaN to cell 0), computed at build time in float32 operation by operation as
    the kernel computes it. Cell c stores the first interval an angle in it can lie in:
    the number of interior nodes (1 .. n-2) whose own cell is below c. The interior nodes
    of one cell bound the search there (a node of a later cell is above every angle of
    cell c): ``steps`` fixed binary-search steps, the bit length of ``max_span``, the most
    interior nodes in one cell (a Python int, so the kernel's loop is unrolled). Both the
    cell and the interval index are monotone in theta, so the result is exactly
    ``mi.math.find_interval``'s over all nodes for every float32 angle (checked on every
    float32 in [0, 3.2] for the default 1, 5 and 20 um tables). The default tables of
    1 / 5 / 20 um DEHS droplets give G = 8192 / 65536 / 131072 (9-16 cells per node),
    ``max_span`` 3 / 4 / 7 and 2 / 3 / 3 steps; a 40 um droplet 5, a fixed ``angles``
    table 1.

    ``nodes`` (``mi.Float``) and ``n`` are the table's; ``cells``, ``max_span``, ``steps``
    describe the grid.
    """

    CELLS_PER_NODE = 4  # the smallest grid, in cells per node; doubled while that saves a step
    MAX_CELLS_PER_NODE = 16
    MAX_CELLS = 1 << 22  # 16 MiB of cell starts (fixed tables of > 1M angles)

    def __init__(self, nodes, cells: int | None = None):
        th = np.ascontiguousarray(nodes, dtype=np.float32)
        n = int(th.size)
        if n < 2:
            raise ValueError(f"AngleNodes: a table needs at least 2 nodes, got {n}.")
        self.nodes, self.n = mi.Float(th), n
        if cells is not None:
            self._grid(th, int(cells))
        else:
            g = min(1 << int(math.ceil(math.log2(self.CELLS_PER_NODE * n))), self.MAX_CELLS)
            self._grid(th, g)
            while 2 * g <= min(self.MAX_CELLS_PER_NODE * n, self.MAX_CELLS):
                fewer = self.steps
                self._grid(th, 2 * g)
                if self.steps >= fewer:  # no step saved: keep the smaller grid
                    self._grid(th, g)
                    break
                g *= 2
        self.start = mi.UInt32(self._start.astype(np.uint32))
        del self._start

    def _grid(self, th: np.ndarray, cells: int) -> None:
        """Grid of ``cells`` cells over the float32 nodes ``th`` (NumPy; sets scale, start, steps)."""
        n = th.size
        with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
            scale = np.float32(cells / (float(th[-1]) - float(th[0])))
        if not np.isfinite(scale) or scale <= 0:
            scale = np.float32(0.0)  # degenerate range: one cell, a plain binary search
        self.cells, self.lo, self.scale, self.top = cells, float(th[0]), float(scale), float(cells - 1)
        cell = self._cell_np(th[1:n - 1])  # cells of the interior nodes 1 .. n-2 (non-decreasing)
        self._start = np.searchsorted(cell, np.arange(cells), side="left")  # interior nodes below cell c
        span = np.diff(np.append(self._start, n - 2))  # interior nodes in cell c
        self.max_span = int(span.max())
        self.steps = self.max_span.bit_length()

    def _cell_np(self, theta: np.ndarray) -> np.ndarray:
        """Cells of float32 angles, in float32 operation by operation as :meth:`cell` computes them."""
        u = (np.asarray(theta, np.float32) - np.float32(self.lo)) * np.float32(self.scale)
        return np.where(u > 0, np.minimum(u, np.float32(self.top)), np.float32(0.0)).astype(np.int64)

    def cell(self, theta):
        """Grid cell of ``theta`` (Dr.Jit), as :meth:`_cell_np`."""
        u = (theta - self.lo) * self.scale
        return mi.UInt32(dr.select(u > 0, dr.minimum(u, self.top), 0.0))


def interval(table: AngleNodes, theta):
    """Index i with nodes[i] <= theta < nodes[i+1], the fraction t in [0, 1] and the width.

    ``i`` is exactly ``mi.math.find_interval`` over the nodes (clamped to [0, n-2]; NaN
    gives 0), found in ``table``'s acceleration grid: one gather for the angle's first
    candidate interval, then ``table.steps`` fixed binary-search steps (2-3 for the default
    1-20 um tables, instead of ~14 over all their nodes; see :class:`AngleNodes`).
    """
    nodes, last = table.nodes, table.n - 2
    i = dr.gather(mi.UInt32, table.start, table.cell(theta))
    for s in reversed([1 << b for b in range(table.steps)]):  # unrolled: steps is a Python int
        k = dr.minimum(i + s, last)
        i = dr.select(dr.gather(mi.Float, nodes, k) <= theta, k, i)
    t0 = dr.gather(mi.Float, nodes, i)
    width = dr.gather(mi.Float, nodes, i + 1) - t0
    return i, dr.clip((theta - t0) / width, 0.0, 1.0), width


class MiePhase(mi.PhaseFunction):
    """Mie phase function; see the module docstring for parameters."""

    is_mie = True  # tracer_particles asks for cross-sections and polarised tables

    def __init__(self, props: mi.Properties):
        super().__init__(props)
        rd = PropertyReader(props, "mie")
        d = rd.float("diameter_um", None)
        gstd = rd.float("geometric_std", None)
        dlist = rd.string("diameters_um", None)
        wlist = rd.string("weights", None)
        n = rd.float("index", 1.45)
        k = rd.float("index_imag", 0.0)
        self.medium_index = check_positive("medium_index", rd.float("medium_index", 1.0), owner="mie")
        wl = rd.float("wavelength_nm", None)
        self.wavelength_nm = None if wl is None else check_positive("wavelength_nm", wl, owner="mie", unit="nm")
        self.angles = rd.int("angles", None)
        tol = rd.float("tolerance", None)
        self.size_step = check_positive("size_step", rd.float("size_step", 0.02), owner="mie")
        rd.finish()
        self.angles, self.tolerance = mie.check_table_settings(self.angles, tol)
        if k < 0:
            raise ConfigError(f"mie: 'index_imag' must be >= 0 (the index is n + ik), got {k!r}.")
        self.m_particle = complex(check_positive("index", n, owner="mie"), k)
        if n < 1.0 and k < 1.0:
            import warnings

            from mitpiv.errors import MitpivWarning

            warnings.warn(f"mie: particle 'index' = {n:g} (absorption {k:g}) is below 1: no dielectric has a "
                          f"refractive index < 1 at optical wavelengths (metals do, with 'index_imag' > 1). For a "
                          f"bubble or a particle less dense than its medium give the medium's index as "
                          f"'medium_index' and the particle's own (absolute) index.", MitpivWarning, stacklevel=2)
        if dlist is not None:
            if d is not None or gstd is not None:
                raise ConfigError("mie: give either 'diameters_um' (with 'weights') or 'diameter_um' (with 'geometric_std'), not both.")
            ds = _floats(dlist, "diameters_um")
            ws = None if wlist is None else _floats(wlist, "weights")
            self.size = mie.SizeDistribution(ds, ws)
        elif wlist is not None:
            raise ConfigError("mie: 'weights' needs 'diameters_um'.")
        elif gstd is not None:
            if d is None:
                raise ConfigError("mie: 'geometric_std' needs 'diameter_um' (the median).")
            self.size = mie.lognormal(check_positive("diameter_um", d, owner="mie", unit="um"), gstd)
        else:
            self.size = None if d is None else check_positive("diameter_um", d, owner="mie", unit="um")
        self._distr = None
        self._last_table = None
        #: set by tracer_particles, which reads this plugin's cross-section table instead
        self.nested_in_tracer = False
        if self.size is not None:
            self._build(self.wavelength_nm or 532.0)
        self.m_flags = mi.PhaseFunctionFlags.Anisotropic
        self.m_components = [self.m_flags]

    # ------------------------------------------------------------------ tables
    def table(self, diameters_um=None, wavelength_nm=None) -> mie.PhaseTable:
        """Phase table (NumPy) for this plugin's particle or for the given diameters."""
        size = self.size if diameters_um is None else diameters_um
        if size is None:
            raise ConfigError("mie: no particle size: give 'diameter_um' (or a distribution), or nest it in "
                              "tracer_particles with a particle file that has diameters.")
        wl = wavelength_nm or self.wavelength_nm or 532.0
        if self.wavelength_nm is not None and wavelength_nm is not None and abs(self.wavelength_nm - wavelength_nm) > 1e-9:
            raise ConfigError(f"mie: 'wavelength_nm' = {self.wavelength_nm} differs from the laser's {wavelength_nm} nm; "
                              f"leave it out to use the laser's.")
        kw = {"angles": self.angles} if self.angles is not None else {"tolerance": self.tolerance}
        return mie.phase_table(size, self.m_particle, wavelength_nm=wl, n_medium=self.medium_index, **kw)

    def cross_section_table(self, diameters_um=None, wavelength_nm=None) -> dict:
        """Differential cross-sections [mm^2/sr] for ``tracer_particles`` (NumPy, float64).

        ``diameters_um``: the per-particle diameters of a particle file, or None for this
        plugin's own size. Rows are diameters equally spaced by ``size_step`` in x from the
        smallest to the largest (one row when all are equal); columns the ascending
        scattering angles ``theta`` [rad]. Returns ``theta``, ``d0_um``, ``dd_um`` (row
        spacing, 0 for one row), ``par`` and ``per`` (rows x angles), ``csca_mm2`` (rows).
        """
        if diameters_um is not None and self.size is not None:
            raise ConfigError(
                "mie: the particle file gives per-particle diameters; remove 'diameter_um' / the size "
                "distribution from the nested mie phase (they are for media and files without diameters)."
            )
        if diameters_um is None:
            t, d0, dd = self.table(wavelength_nm=wavelength_nm), 0.0, 0.0
        else:
            d = np.asarray(diameters_um, dtype=np.float64)
            lo, hi = float(d.min()), float(d.max())
            wl = wavelength_nm or self.wavelength_nm or 532.0
            step_um = self.size_step * wl * 1e-3 / (math.pi * self.medium_index)
            rows = 1 if hi - lo <= 1e-9 * hi else int(math.ceil((hi - lo) / step_um)) + 1
            grid = np.linspace(lo, hi, rows) if rows > 1 else np.array([lo])
            t = self.table(grid, wavelength_nm=wavelength_nm)
            d0, dd = lo, (grid[1] - grid[0]) if rows > 1 else 0.0
        c = t.csca_mm2[:, None]
        self._last_table = t
        return {"theta": t.theta[::-1].copy(), "d0_um": d0, "dd_um": dd, "csca_mm2": t.csca_mm2.copy(),
                "par": (c * t.p_par)[:, ::-1].copy(), "per": (c * t.p_per)[:, ::-1].copy(),
                "max_error": t.max_error}

    def _build(self, wavelength_nm):
        t = self.table(wavelength_nm=wavelength_nm)
        theta = t.theta[::-1].copy()  # ascending angle
        g = 2 * math.pi * np.sin(theta) * t.phase[0][::-1]
        g[0] = g[-1] = 0.0
        g /= np.sum(0.5 * (g[1:] + g[:-1]) * np.diff(theta))  # the interpolant integrates to 1
        self._theta_np, self._g_np = theta, g
        self._n = theta.size
        self._nodes = AngleNodes(theta)  # the float32 nodes, with the grid of the interval lookup
        self._theta = self._nodes.nodes
        self._g = mi.Float(g.astype(np.float32))
        self._distr = mi.IrregularContinuousDistribution(self._theta, self._g)
        self._table = self._last_table = t

    def _require(self) -> bool:
        """True when this phase has a table to sample and evaluate.

        Without a particle size it has none: an error for a medium's phase, but not for one
        nested in ``tracer_particles`` (which reads :meth:`cross_section_table`). Dr.Jit traces
        the methods of every live phase function whenever any medium's phase is dispatched,
        so a nested instance from another scene still alive in the process must trace
        cleanly: it returns zeros (it is never reached at run time)."""
        if self._distr is not None:
            return True
        if self.nested_in_tracer:
            return False
        raise ConfigError("mie: no particle size: give 'diameter_um' (or a distribution) to use it outside tracer_particles.")

    def pdf_theta(self, theta):
        """Phase function [1/sr] at scattering angles ``theta`` [rad] (the table's interpolant)."""
        if not self._require():
            return dr.zeros(mi.Float, dr.width(theta))
        i, t, width = interval(self._nodes, theta)
        g0 = dr.gather(mi.Float, self._g, i)
        g1 = dr.gather(mi.Float, self._g, i + 1)
        g = dr.lerp(g0, g1, t)
        s = dr.sin(theta)
        # End intervals: g vanishes at 0 and pi like sin(theta); divide the slope instead.
        first = i == 0
        last = i == self._n - 2
        x = dr.select(first, theta, dr.pi - theta)
        x_over_sin = dr.select(x > 1e-4, x / dr.maximum(s, 1e-30), 1.0)
        end = dr.select(first, g1, g0) / width * x_over_sin
        val = dr.select(first | last, end, g / dr.maximum(s, 1e-30))
        return val * (0.5 / math.pi)

    # ------------------------------------------------------------------ PhaseFunction interface
    def sample(self, ctx, mei, sample1, sample2, active=True):
        if not self._require():
            return dr.zeros(mi.Vector3f, dr.width(sample1)), mi.Spectrum(0.0), dr.zeros(mi.Float, dr.width(sample1))
        theta = self._distr.sample(sample2.x, active)
        sin_t, cos_t = dr.sincos(theta)
        sin_p, cos_p = dr.sincos(2.0 * dr.pi * sample2.y)
        wo = -mei.to_world(mi.Vector3f(sin_t * cos_p, sin_t * sin_p, cos_t))
        pdf = self.pdf_theta(theta)
        return wo, mi.Spectrum(1.0), pdf

    def eval_pdf(self, ctx, mei, wo, active=True):
        theta = scattering_angle(wo, -mei.wi)
        pdf = self.pdf_theta(theta)
        return mi.Spectrum(pdf), pdf

    def to_string(self):
        return (f"MiePhase[size={self.size!r}, m={self.m_particle}, medium={self.medium_index}, "
                f"wavelength={self.wavelength_nm}, angles={self.angles}, tolerance={self.tolerance}]")

    def describe(self) -> dict:
        size = self.size
        if isinstance(size, mie.SizeDistribution):
            size = {"diameters_um": size.diameters_um.tolist(), "weights": size.weights.tolist()}
        return {"type": "mie", "size_um": size, "index": [self.m_particle.real, self.m_particle.imag],
                "medium_index": self.medium_index, "wavelength_nm": self.wavelength_nm, **self.table_info()}

    def table_info(self) -> dict:
        """The table's settings and what they gave: ``angles`` (nodes of the last table built, or
        the fixed count), ``tolerance`` (None for fixed ``angles``), ``max_error`` (relative,
        at the nodes' midpoints of the row the grid was chosen on; None before a table is built)."""
        t = self._last_table
        return {"angles": t.angles if t is not None else self.angles, "tolerance": self.tolerance,
                "max_error": None if t is None else float(t.max_error)}


mi.register_phase("mie", lambda props: MiePhase(props))
