"""Mitsuba variant selection and plugin registration.

Importing mitpiv selects nothing (and imports neither Mitsuba nor Dr.Jit). The first
operation that builds Mitsuba objects with mitpiv's plugins calls :func:`ensure_variant`,
which keeps a supported variant that is already active and otherwise calls
:func:`set_variant`. ``set_variant()`` picks ``cuda_ad_mono`` when a CUDA device works, else
``llvm_ad_mono``; the environment variable ``MITPIV_VARIANT`` overrides both. Dr.Jit's LLVM backend needs
LLVM >= 16 (older versions fail to compile kernels with "Cannot select: fmaximum"): that
is checked here, with an error naming the fix. mitpiv's plugins are registered for the
variant, and re-registered by a variant callback whenever the variant changes.
"""

from __future__ import annotations

import logging
import os

from mitpiv.errors import BackendError, ConfigError

__all__ = ["set_variant", "ensure_variant", "current_variant", "SUPPORTED", "LLVM_FIX", "llvm_version"]

log = logging.getLogger(__name__)

MIN_LLVM = (16, 0, 0)
SUPPORTED = ("llvm_ad_mono", "cuda_ad_mono")
LLVM_FIX = (
    "Install a newer LLVM and let Dr.Jit find it: on Debian/Ubuntu run "
    "'sudo apt-get install libllvm19' (or set DRJIT_LIBLLVM_PATH to a libLLVM.so of "
    "version >= 16). 'make setup' does this when run as root."
)

_callback_installed = False


def llvm_version() -> tuple[int, int, int] | None:
    """The LLVM version Dr.Jit loaded, or None if none could be loaded."""
    import drjit as dr

    try:
        v = dr.detail.llvm_version()
    except Exception:
        return None
    return tuple(int(x) for x in v) if v else None


def _check_llvm() -> None:
    v = llvm_version()
    if v is None:
        raise BackendError(f"Dr.Jit's LLVM backend found no libLLVM. {LLVM_FIX}")
    if v < MIN_LLVM:
        raise BackendError(
            f"Dr.Jit loaded LLVM {'.'.join(map(str, v))}, which cannot compile its kernels "
            f"(LLVM >= 16 is needed; older versions fail with 'Cannot select: fmaximum'). {LLVM_FIX}"
        )


def current_variant() -> str | None:
    """The active Mitsuba variant, or None (also None when Mitsuba has not been imported:
    asking does not import it)."""
    import sys

    mi = sys.modules.get("mitsuba")
    return None if mi is None else mi.variant()


def _env_variant() -> str | None:
    """``$MITPIV_VARIANT``, checked: None when unset or empty."""
    env = os.environ.get("MITPIV_VARIANT", "").strip() or None
    if env is not None and env not in SUPPORTED:
        raise ConfigError(
            f"MITPIV_VARIANT={env!r} is not a supported Mitsuba variant; set it to one of {', '.join(SUPPORTED)} "
            f"or unset it (mitpiv's plugins need a vectorised '*_ad_mono' variant)."
        )
    return env


def ensure_variant() -> str:
    """Make sure a supported variant is active and mitpiv's plugins are registered for it.

    Called by every entry point that builds Mitsuba objects with mitpiv's plugins
    (:func:`mitpiv.render.scene.load_scene`, :func:`~mitpiv.render.scene.load_dict`,
    target and backlit scenes). A supported variant that is already active (chosen by
    :func:`set_variant` or by ``mitsuba.set_variant``) is kept; otherwise the default is
    selected as :func:`set_variant` does (``$MITPIV_VARIANT``, else ``cuda_ad_mono`` when a
    CUDA device works, else ``llvm_ad_mono``). Cheap when there is nothing to do.

    Returns
    -------
    str
        The variant now active.

    Raises
    ------
    ConfigError
        ``MITPIV_VARIANT`` names an unsupported variant.
    BackendError
        No supported variant can be used on this machine.
    """
    _env_variant()
    active = current_variant()
    if active in SUPPORTED and _callback_installed:
        from mitpiv.render.plugins import register_all

        register_all()  # no-op when the plugins were built for this variant
        return active
    if active in SUPPORTED:  # selected with mitsuba.set_variant before mitpiv saw it
        return set_variant(active)
    return set_variant()


def _on_variant_change(old, new) -> None:
    if new is not None and new in SUPPORTED:
        from mitpiv.render.plugins import register_all

        register_all()


def set_variant(name: str | None = None) -> str:
    """Select the Mitsuba variant and register mitpiv's plugins for it.

    Parameters
    ----------
    name : str, optional
        ``"llvm_ad_mono"`` or ``"cuda_ad_mono"``. Default: ``$MITPIV_VARIANT`` if set,
        else ``cuda_ad_mono`` when a CUDA device works, else ``llvm_ad_mono``.

    Returns
    -------
    str
        The variant now active.
    """
    global _callback_installed
    import mitsuba as mi

    before = mi.variant()
    requested = name or _env_variant()
    if requested is not None and requested not in SUPPORTED:
        raise ConfigError(
            f"set_variant: variant {requested!r} is not supported; use one of {', '.join(SUPPORTED)} "
            f"(mitpiv's plugins need a vectorised '*_ad_mono' variant)."
        )
    if not _callback_installed:
        mi.detail.add_variant_callback(_on_variant_change)
        _callback_installed = True
    if requested is None:
        try:
            mi.set_variant("cuda_ad_mono")
            chosen = "cuda_ad_mono"
        except Exception:
            chosen = "llvm_ad_mono"
    else:
        chosen = requested
    if chosen == "llvm_ad_mono":
        _check_llvm()
    if mi.variant() != chosen:
        try:
            mi.set_variant(chosen)
        except Exception as e:
            raise BackendError(f"set_variant: Mitsuba variant {chosen!r} cannot be used here: {e}") from None
    else:
        # The callback only fires on a change; make sure plugins exist for this variant.
        from mitpiv.render.plugins import register_all

        register_all()
    if before != chosen:
        log.info("Mitsuba variant %s selected (was %s); mitpiv's plugins registered", chosen, before)
    return chosen
