"""Test-suite settings: progress bars off (tests run silent), and the Mitsuba variant selected
once for the whole session.

Importing mitpiv selects no variant (the first render does, see
:func:`mitpiv.render.variant.ensure_variant`), but many tests build Mitsuba values
(``mi.ScalarTransform4f``, ``mi.load_dict``) themselves, some at module level, so the
variant is chosen here before collection: the same default a first render would pick
(``$MITPIV_VARIANT``, else ``cuda_ad_mono`` when a CUDA device works, else
``llvm_ad_mono``). The lazy path itself is tested in fresh interpreters
(tests/render/test_variant.py).
"""

import os

os.environ.setdefault("MITPIV_QUIET", "1")

import mitpiv  # noqa: E402

try:
    mitpiv.set_variant()
except mitpiv.BackendError:  # pragma: no cover - no rendering backend on this machine
    pass  # the NumPy tests still run; every rendering test fails with this error (ensure_variant raises it)

try:  # property tests (Hypothesis): the same examples on every run, so CI is reproducible
    from hypothesis import settings as _hyp_settings

    _hyp_settings.register_profile("mitpiv", derandomize=True, database=None)
    _hyp_settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "mitpiv"))
except ImportError:  # pragma: no cover - hypothesis is in the test extra
    pass
