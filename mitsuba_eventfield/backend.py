"""Mitsuba variant selection: CUDA when a GPU is usable, else LLVM; mono unless colour is requested.

Our plugins are Python classes. Under a ``scalar_*`` variant Mitsuba calls them once per sample (about 90x
slower than the vectorised variants, docs/design.md, "Measured facts and pitfalls"), so scalar variants are refused with an explanation
rather than used silently.
"""
from __future__ import annotations

from . import _llvm
from .errors import EventFieldError

_llvm.configure()

import drjit as dr  # noqa: E402  (must follow the libLLVM configuration)
import mitsuba as mi  # noqa: E402

_active: str | None = None
_QUIET_MESSAGES = (
    # hdrfilm's default pixel format is rgb; under mono variants Mitsuba switches it and says so on every load
    "Monochrome mode enabled, setting film output pixel format",
)


def _install_log_filter() -> None:
    """Route Mitsuba's log to stderr, minus messages that are expected and say nothing to our users."""
    class _FilteringAppender(mi.Appender):
        def append(self, level, text):
            if not any(q in text for q in _QUIET_MESSAGES):
                print(text, file=__import__("sys").stderr)

        def log_progress(self, progress, name, formatted, eta, ptr=None):
            pass

    logger = mi.logger()
    if logger is not None:
        logger.clear_appenders()
        logger.add_appender(_FilteringAppender())


def available_backends() -> dict:
    return {"cuda": bool(dr.has_backend(dr.JitBackend.CUDA)), "llvm": bool(dr.has_backend(dr.JitBackend.LLVM))}


def choose_variant(variant: str | None = None, color: bool = False) -> str:
    """Return the variant to use. ``variant`` is an explicit override ('llvm_ad_rgb', 'cuda', 'llvm', ...)."""
    mode = "rgb" if color else "mono"
    compiled = set(mi.variants())
    backends = available_backends()
    if variant:
        if variant in ("cuda", "llvm"):
            variant = f"{variant}_ad_{mode}"
        if variant.startswith("scalar"):
            raise EventFieldError(
                f"variant '{variant}': scalar variants run our Python plugins once per sample (~90x slower); "
                "use an llvm_ad_* or cuda_ad_* variant")
        if variant not in compiled:
            raise EventFieldError(f"variant '{variant}' is not compiled into this Mitsuba; allowed: "
                                  + ", ".join(sorted(v for v in compiled if not v.startswith("scalar"))))
        backend = variant.split("_", 1)[0]
        if not backends.get(backend, False):
            raise EventFieldError(f"variant '{variant}': the {backend.upper()} backend is not usable on this machine"
                                  + (_llvm_hint() if backend == "llvm" else ""))
        return variant
    for backend in ("cuda", "llvm"):
        if backends[backend] and f"{backend}_ad_{mode}" in compiled:
            return f"{backend}_ad_{mode}"
    raise EventFieldError("no vectorised Mitsuba variant is usable (neither CUDA nor LLVM); only scalar variants "
                          "would work and they are ~90x slower for our plugins." + _llvm_hint())


def _llvm_hint() -> str:
    path, found = _llvm.find_libllvm()
    if path is None:
        return (f" Dr.Jit needs libLLVM >= {_llvm.MIN_LLVM_MAJOR} (found: {', '.join(found) or 'none'}); "
                "install one, e.g. `apt-get install libllvm19`, or set DRJIT_LIBLLVM_PATH.")
    return f" (DRJIT_LIBLLVM_PATH={__import__('os').environ.get('DRJIT_LIBLLVM_PATH')})"


def set_variant(variant: str | None = None, color: bool = False) -> str:
    """Activate a variant (see :func:`choose_variant`) and register our plugins for it. Idempotent."""
    global _active
    chosen = choose_variant(variant, color)
    if _active != chosen or mi.variant() != chosen:
        mi.set_variant(chosen)
        _install_log_filter()
        from . import plugins  # noqa: F401  (plugins are registered per variant)
        plugins.register()
        _active = chosen
    return chosen


def ensure_variant(color: bool = False) -> str:
    """Use the active variant if one of ours is set, otherwise choose one."""
    if _active is not None and mi.variant() == _active:
        return _active
    return set_variant(color=color)
