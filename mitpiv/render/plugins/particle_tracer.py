"""``particle_tracer``: light tracing from tracer particles straight into the sensor.

Parameters
----------
rays_per_particle : integer, default 16, range >= 1
    Sensor samples per particle and pass (aperture points of a thin-lens camera, PSF
    offsets of a ``jitter`` PSF). A sensor without such samples (a pinhole) has a single
    direction to each particle, so it always uses 1 (at the sensor's centre sample).
occlusion : boolean, default false
    Cast a shadow ray from each particle to the sensor (other particles' proxies and
    any scene geometry occlude); off: all particles are seen.
batch_rays : integer, default 16777216, range >= 1024
    Rays traced per kernel launch: a pass over ``N x rays_per_particle`` rays runs in
    consecutive batches of at most this many, so memory stays bounded (about 30 bytes per
    ray in flight: 0.5 GiB at the default) for any particle count and ray budget. Rounded
    down to a multiple of 1024, so that batches start on the CPU's vector packets: the
    image is then bit-identical for every batch size (same random sequences, splats summed
    in the same order and grouped into the same packets).

Notes
-----
For each particle ``i`` and ray ``j`` the sensor's ``sample_direction`` gives the pixel
position ``uv``, the direction ``w`` toward the sensor and the importance weight ``W``;
the value ``I_i(w) W N_pixels / rays`` is splatted at ``uv`` with the film's
reconstruction filter.

``spp`` (``mi.render(..., spp=N)``, mitpiv's ``render_scene(spp=N)``) is honoured as ``N``
independent passes of ``rays_per_particle`` rays each, averaged: ``N x rays_per_particle``
samples per particle, so the Monte Carlo variance falls as ``1 / N``. ``spp=0`` (not
given) is one pass: the tracer does not take the sensor sampler's ``sample_count``, whose
default (4) would silently quadruple the cost; ``rays_per_particle`` is its budget. A sensor
without samples (pinhole, no jitter PSF) gives the same image on every pass, so it is
rendered once, exactly. :attr:`ParticleTracer.last_stats` says what the last render used
(``passes``, ``rays_per_particle``, ``samples_per_particle``, ``spp_requested``).

Random streams: the aperture / PSF samples of emitter ``k`` seen by sensor ``id`` come from
PCG32 sequences whose initial state is ``mitpiv.streams.derived_seed(seed,
"particle_tracer", id, k)`` (the render's seed, the sensor's id and the emitter's index hashed
by NumPy's SeedSequence), one sequence per particle ray and pass. Two cameras rendered with
the same seed therefore draw independent samples; :func:`mitpiv.render.render_scene`
(and ``render_sensor(..., frame=f)``) also give every camera and frame its own seed.

Determinism: the rays are traced in parallel, but their splats are accumulated into the
image on one CPU thread, in ray order (LLVM variants). Float additions into one pixel in a
thread-dependent order made same-seed images differ in the last bits (about a third of the
pixels of a 128 px render); accumulated serially, a render is bit-identical for a seed on one
machine and variant. The serial accumulation costs one pass over the splats (a gather and a
few scatter-adds per splat and filter tap). On CUDA variants the GPU's atomic additions keep
an unspecified order: pixels may differ by float32 rounding of their sum (see
:data:`mitpiv.render.render.DETERMINISM`).

This is the particle-tracing estimator of the image that camera
tracing (Mitsuba's ``direct`` integrator) estimates pixel by pixel, so both agree within
their noise. Works with ``distorted_pinhole`` and with Mitsuba's ``perspective`` and
``thinlens`` sensors. Only single scattering from particles is traced (no light paths
through other surfaces).

.. code-block:: xml

    <integrator type="particle_tracer">
        <integer name="rays_per_particle" value="64"/>
        <boolean name="occlusion" value="true"/>
    </integrator>
"""

from __future__ import annotations

import numbers
from contextlib import contextmanager

import drjit as dr
import mitsuba as mi

from mitpiv.errors import ConfigError
from mitpiv.render.plugins._props import PropertyReader
from mitpiv.streams import derived_seed

_VARIANT = mi.variant()

#: Default rays per kernel launch (``batch_rays``): 2^24.
DEFAULT_BATCH_RAYS = 1 << 24

#: Batches hold a multiple of this many rays. Dr.Jit's LLVM kernels sum the scatter-adds of
#: one vector packet (4-16 lanes) that hit the same pixel before adding them to the image,
#: so a batch that started inside a packet would round some pixels differently (1 ulp).
BATCH_ALIGN = 1024

#: Largest ``rays_per_particle``: a batch's ray index within its first particle plus the
#: batch size must fit the 32-bit lane index.
MAX_RAYS_PER_PARTICLE = 1 << 31


def batches(n: int, rays: int, batch: int):
    """Consecutive slices of the flat ray index ``k = particle * rays + ray`` (``0 <= k < n
    rays``), each at most ``batch`` rays: ``(first particle, first ray within it, count)``.
    Pure integer arithmetic (Python ints, no overflow)."""
    total, start = n * rays, 0
    while start < total:
        count = min(batch, total - start)
        yield start // rays, start % rays, count
        start += count


def _seed_int(seed) -> int:
    """The render seed as a Python int (``mi.render`` passes what the caller gave: an int or
    a one-entry ``mi.UInt32``)."""
    if isinstance(seed, numbers.Integral):
        return int(seed)
    if dr.is_array_v(seed) and dr.width(seed) == 1:
        return int(seed[0])
    raise ConfigError(f"particle_tracer: the render seed must be one non-negative integer, got {seed!r}.")


@contextmanager
def serial_accumulation():
    """Run the Dr.Jit kernels launched inside on one CPU thread (LLVM variants; nothing
    changes on CUDA): scatter-additions then happen in lane order, so float sums into one
    pixel are bit-reproducible. The thread count is restored afterwards."""
    if not _VARIANT.startswith("llvm"):
        yield
        return
    n, expand = dr.thread_count(), dr.expand_threshold()
    dr.sync_thread()  # kernels launch asynchronously: none may run while the pool changes
    dr.set_thread_count(1)
    dr.set_expand_threshold(0)  # no per-thread copies of the target (sized by the pool)
    try:
        yield
        dr.sync_thread()
    finally:
        dr.set_expand_threshold(expand)
        dr.set_thread_count(n)


class ParticleTracer(mi.CppADIntegrator):
    """Particle light tracer; see the module docstring for parameters."""

    def __init__(self, props: mi.Properties):
        super().__init__(props)
        rd = PropertyReader(props, "particle_tracer")
        self.rays_per_particle = rd.int("rays_per_particle", 16)
        if not 1 <= self.rays_per_particle <= MAX_RAYS_PER_PARTICLE:
            raise ConfigError(f"particle_tracer: 'rays_per_particle' must lie in [1, {MAX_RAYS_PER_PARTICLE}], got "
                              f"{self.rays_per_particle}; use spp (independent passes) for more samples per particle.")
        self.occlusion = rd.bool("occlusion", False)
        batch = rd.int("batch_rays", DEFAULT_BATCH_RAYS)
        if batch < BATCH_ALIGN:
            raise ConfigError(f"particle_tracer: 'batch_rays' must be >= {BATCH_ALIGN}, got {batch}; the default is "
                              f"{DEFAULT_BATCH_RAYS} (about 0.5 GiB of rays in flight).")
        self.batch_rays = batch - batch % BATCH_ALIGN
        rd.finish()
        self.last_stats = {}

    @staticmethod
    def particle_emitters(scene):
        return [s.emitter() for s in scene.shapes() if s.emitter() is not None and hasattr(s.emitter(), "particle_arrays")]

    def rays_for(self, sensor) -> int:
        return self.rays_per_particle if sensor.needs_aperture_sample() else 1

    def passes_for(self, sensor, spp: int = 0) -> int:
        """Independent passes a render with ``spp`` makes: ``spp`` (1 when 0) for a sensor
        that draws samples, 1 for a deterministic one (every pass would be the same)."""
        spp = int(spp)
        if spp < 0:
            raise ConfigError(f"particle_tracer: 'spp' must be >= 0 (0: one pass), got {spp}.")
        return max(spp, 1) if sensor.needs_aperture_sample() else 1

    def render(self, scene, sensor=0, seed=0, spp=0, develop=True, evaluate=True):
        if isinstance(sensor, int):
            sensor = scene.sensors()[sensor]
        film = sensor.film()
        size = film.size()
        n_pix = float(size[0] * size[1])
        block = mi.ImageBlock(size, mi.ScalarPoint2i(0, 0), 1, film.rfilter(), False, True, False, False, False)
        rays = self.rays_for(sensor)
        passes = self.passes_for(sensor, spp)
        seed = _seed_int(seed)
        sid = sensor.id() or ""
        splats = batch_count = 0
        for k, emitter in enumerate(self.particle_emitters(scene)):
            center, radius, diameter = emitter.particle_arrays()
            n = dr.width(diameter)
            if n == 0:
                continue
            state = derived_seed(seed, "particle_tracer", sid, k)  # this sensor's and emitter's stream
            for pas in range(passes):
                for p0, r0, count in batches(n, rays, self.batch_rays):
                    self._trace_batch(scene, sensor, emitter, block, (center, radius, diameter),
                                      p0, r0, count, rays, pas * n * rays, state, n_pix / (rays * passes))
                    batch_count += 1
                splats += n * rays
        self.last_stats = {"rays_per_particle": rays, "passes": passes, "samples_per_particle": rays * passes,
                           "spp_requested": int(spp) if spp else None, "splats": splats,
                           "occlusion": self.occlusion, "batches": batch_count, "batch_rays": self.batch_rays}
        img = block.tensor()
        if evaluate:
            dr.eval(img)
        return img

    def _trace_batch(self, scene, sensor, emitter, block, arrays, p0, r0, count, rays, pass_offset, state, scale):
        """Trace ``count`` rays of flat indices ``k = p0 rays + r0 + j`` (``j < count``) and
        splat them into ``block``. Ray ``k`` of pass ``p`` seeds its PCG32 generator with state
        ``S + k`` and sequence ``2 k + p N rays`` (``S`` the emitter's stream; what
        ``PCG32(size=N rays, initstate=S, initseq=k + p N rays)`` gives lane ``k``, the
        unbatched form): pass 0 is the single-pass render, no two rays of a render share a
        (state, sequence) pair, and the batching leaves every ray's sample unchanged. The
        batch's offsets are opaque, so every batch, pass and seed reuses one compiled kernel."""
        center, radius, diameter = arrays
        local = dr.arange(mi.UInt32, count) + dr.opaque(mi.UInt32, r0)  # < rays + batch_rays < 2^32
        pid = local // rays + dr.opaque(mi.UInt32, p0)
        it = dr.zeros(mi.Interaction3f, count)
        it.p = dr.gather(mi.Point3f, center, pid)
        it.time = mi.Float(sensor.shutter_open())
        if sensor.needs_aperture_sample():
            k = mi.UInt64(local) + dr.opaque(mi.UInt64, p0 * rays)
            rng = mi.PCG32(size=count)
            rng.seed(initstate=k + dr.opaque(mi.UInt64, state), initseq=2 * k + dr.opaque(mi.UInt64, pass_offset))
            sample = mi.Point2f(rng.next_float32(), rng.next_float32())
        else:
            sample = mi.Point2f(0.5, 0.5)
        ds, w_sensor = sensor.sample_direction(it, sample, True)
        active = ds.pdf > 0
        if self.occlusion:
            # Start outside the particle's own proxy shell (circumradius < 1.3 R).
            skip = 1.5 * dr.gather(mi.Float, radius, pid)
            ray = mi.Ray3f(it.p + ds.d * skip, ds.d, ds.dist - skip, it.time, it.wavelengths)
            active &= ~scene.ray_test(ray, active)
        intensity = emitter.intensity(it.p, dr.gather(mi.Float, diameter, pid), ds.d, it.wavelengths, active)
        value = intensity * w_sensor[0] * scale
        uv = mi.Point2f(ds.uv)
        dr.eval(uv, value, active)  # the rays, traced in parallel
        with serial_accumulation():  # their splats, summed in ray order (module docstring)
            block.put(uv, [value], active)
            dr.eval(block.tensor())

    def to_string(self):
        return (f"ParticleTracer[rays_per_particle={self.rays_per_particle}, occlusion={self.occlusion}, "
                f"batch_rays={self.batch_rays}]")


mi.register_integrator("particle_tracer", lambda props: ParticleTracer(props))
