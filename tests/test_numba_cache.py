"""Numba's on-disk cache must hit in a new process.

Its index key hashes each kernel's closure cells; a dispatcher pickles differently in every
process, so a kernel whose closure holds another jitted function was compiled afresh in
every process (10 s of the demo's MART set-up) and its cache grew by one entry each time.
Helpers are therefore module globals. This checks every kernel factory for dispatchers in
closure cells, and that a kernel compiled in one process loads in the next.
"""

import os
import subprocess
import sys

import pytest

from mitpiv.analysis.piv3d import _warp_kernels
from mitpiv.lightfield.refocus import _kernels as refocus_kernels
from mitpiv.physics.flows import _biot_savart_kernel
from mitpiv.reconstruct._kernels import kernels as reconstruct_kernels
from mitpiv.tracking._kernels import kernels as tracking_kernels

FACTORIES = {"reconstruct": reconstruct_kernels, "tracking": tracking_kernels, "piv3d": _warp_kernels,
             "refocus": refocus_kernels, "vortex_ring": lambda: {"biot_savart": _biot_savart_kernel()}}


@pytest.mark.parametrize("name", sorted(FACTORIES))
def test_no_kernel_closes_over_a_dispatcher(name):
    from numba.core.dispatcher import Dispatcher

    kernels = {k: v for k, v in FACTORIES[name]().items() if isinstance(v, Dispatcher)}
    assert kernels, f"{name}: the factory returned no kernel"
    for k, disp in kernels.items():
        cells = disp.py_func.__closure__ or ()
        bad = [c.cell_contents for c in cells if isinstance(c.cell_contents, Dispatcher)]
        assert not bad, f"{name}.{k} closes over jitted {[b.py_func.__name__ for b in bad]}: make them module globals"


def test_a_kernel_calling_a_helper_loads_from_the_cache_in_a_new_process(tmp_path):
    """piv3d's warp_cubic calls bspline3: compiled in one process, loaded in the next."""
    code = ("import numpy as np\n"
            "from mitpiv.analysis.piv3d import _warp_kernels, _spline_coefficients, SPLINE_PAD\n"
            "v = np.random.default_rng(0).random((8, 8, 8)).astype(np.float32)\n"
            "out = np.empty_like(v)\n"
            "_warp_kernels()['warp_cubic'](_spline_coefficients(v), SPLINE_PAD, np.zeros((8, 8, 8, 3), np.float32),"
            " 1.0, out)\n")
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path), "NUMBA_DEBUG_CACHE": "1"}
    logs = [subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True).stdout
            for _ in range(2)]
    first = [ln for ln in logs[0].splitlines() if "warp_cubic" in ln and "data saved" in ln]
    second = [ln for ln in logs[1].splitlines() if "warp_cubic" in ln and "data " in ln]
    assert first, logs[0][-2000:]
    assert second and all("data loaded" in ln for ln in second), logs[1][-2000:]
