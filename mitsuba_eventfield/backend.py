"""Mitsuba variant selection: CUDA when a GPU is usable, else LLVM; mono unless colour is requested.

Our plugins are Python classes. Under a ``scalar_*`` variant Mitsuba calls them once per sample (about 90x
slower than the vectorised variants, docs/design.md, "Measured facts and pitfalls"), so scalar variants are refused with an explanation
rather than used silently.

Mitsuba's log is left as it is unless asked: :func:`quiet_mitsuba_log` (which the ``eventfield`` command uses)
drops the messages that are expected and say nothing to our users.
"""
from __future__ import annotations

import os
import sys

from . import _llvm
from .errors import EventFieldError

_llvm.configure()

import drjit as dr  # noqa: E402  (must follow the libLLVM configuration)
import mitsuba as mi  # noqa: E402

# frozen functions live with the plugins (the lowest layer: the event passes freeze too); re-exported here
from .plugins.frozen import FREEZE_ENV, FrozenOrTraced, freezing  # noqa: E402,F401

_active: str | None = None
_QUIET_MESSAGES = (
    # hdrfilm's default pixel format is rgb; under mono variants Mitsuba switches it and says so on every load
    "Monochrome mode enabled, setting film output pixel format",
    # Ctrl-C inside Mitsuba's render: it logs this, then the KeyboardInterrupt reaches the caller, which reports it
    "Received interrupt signal, winding down",
)
_saved_appenders: list | None = None    # Mitsuba's appenders before quiet_mitsuba_log(), restored by (False)


def mitsuba_log_is_quiet() -> bool:
    """Whether :func:`quiet_mitsuba_log` is on in this process (a sweep's worker processes follow it)."""
    return _saved_appenders is not None


def quiet_mitsuba_log(enable: bool = True) -> bool:
    """Opt in to a quieter Mitsuba log: one appender printing to ``sys.stderr`` that drops the messages which
    are expected and say nothing to our users (``_QUIET_MESSAGES``: the monochrome-film note on every scene load
    under ``*_mono`` variants, the "winding down" line of a Ctrl-C inside ``mi.render``) and progress bars.

    Importing the package, or :func:`set_variant`, never touches Mitsuba's log; the ``eventfield`` command
    calls this for its run and restores the log afterwards. ``quiet_mitsuba_log(False)`` puts back the
    appenders that were there before. Idempotent; Mitsuba's logger is shared by all variants. Returns whether
    the quiet log was on before the call."""
    global _saved_appenders
    if not isinstance(enable, (bool, int)):          # "no" would be truthy: refuse rather than guess
        raise EventFieldError(f"quiet_mitsuba_log: enable = {enable!r}: expected True or False")
    logger = mi.logger()
    was_quiet = _saved_appenders is not None
    if logger is None or bool(enable) == was_quiet:
        return was_quiet
    if enable:
        _saved_appenders = [logger.appender(i) for i in range(logger.appender_count())]
        logger.clear_appenders()
        logger.add_appender(_FilteringAppender())
    else:
        logger.clear_appenders()
        for appender in _saved_appenders:
            logger.add_appender(appender)
        _saved_appenders = None
    return was_quiet


class _FilteringAppender(mi.Appender):
    """Mitsuba's log to ``sys.stderr``, minus ``_QUIET_MESSAGES`` and progress (see :func:`quiet_mitsuba_log`)."""

    def append(self, level, text):
        if not any(q in text for q in _QUIET_MESSAGES):
            print(text, file=sys.stderr)

    def log_progress(self, progress, name, formatted, eta, ptr=None):
        pass


VARIANT_ENV = "EVENTFIELD_VARIANT"      # the backend (cuda, llvm) for any command or script that names none


def available_backends() -> dict:
    return {"cuda": bool(dr.has_backend(dr.JitBackend.CUDA)), "llvm": bool(dr.has_backend(dr.JitBackend.LLVM))}


def choose_variant(variant: str | None = None, color: bool = False) -> str:
    """Return the variant to use. ``variant`` is an explicit override ('llvm_ad_rgb', 'cuda', 'llvm', ...); without
    one, the environment's ``EVENTFIELD_VARIANT`` (every command and script, not only those with ``--variant``)."""
    if variant is None and os.environ.get(VARIANT_ENV):
        named = os.environ[VARIANT_ENV]
        # the backend it names; mono or rgb stays the caller's (a colour probe, a mono bench): "llvm_ad_mono"
        # there made --auto plan a coloured scene as grey
        backend, _, mode = named.partition("_ad_")
        try:
            return choose_variant(backend if mode in ("mono", "rgb") else named, color)
        except EventFieldError as e:
            raise EventFieldError(f"{VARIANT_ENV}={os.environ[VARIANT_ENV]}: {e}") from None
    if variant is not None and not isinstance(variant, str):
        raise EventFieldError(f"variant = {variant!r}: expected a variant name ('llvm_ad_mono', 'cuda', 'llvm', ...) "
                              "or None")
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
        from . import plugins  # noqa: F401  (plugins are registered per variant)
        plugins.register()
        _active = chosen
    return chosen


def ensure_variant(color: bool = False) -> str:
    """Use the active variant if one of ours is set, otherwise choose one."""
    if _active is not None and mi.variant() == _active:
        return _active
    return set_variant(color=color)


OVERLAP_ENV = "EVENTFIELD_OVERLAP"
OVERLAP_NOTE = ("the host prepared each step while the GPU rendered the one before: the render time is the wait "
                "for it, and a stage that waited first (a chunk of events read back) holds some of it; the "
                "wall time is the measure")


def overlaps_steps() -> bool:
    """Whether a render loop stages a step's motion while the device still renders the step before (CUDA), or
    syncs after each render (LLVM): ``simulate/render.py``. On an H100 the sync after each render kept the host
    idle while the GPU rendered; without it the demo's 100 steps took 0.201 s instead of 0.223 s, and the fan's
    400 at 1280x720 took 2.44 s instead of 2.63 s (benchmarks/results/motion_h100.md); on an H200, in
    interleaved pairs, faster in 6 of 6 on both scenes (overlap_h200.md). On the 2-core CPU the evidence is
    mixed: no gain in a first A/B (two runs), then 7 % (demo) and 13 % (fan) by the best of four alternating
    runs, then +0.9 % and +4.2 % by medians in 6 interleaved pairs (overlap.md, docs/design.md). There the
    render's time moves into whichever stage waits first (events 0.02 -> 0.29 s in a demo render), so the CPU
    keeps its exact split by default. ``EVENTFIELD_OVERLAP=1`` / ``0`` chooses either on any backend."""
    return on_cuda_unless(OVERLAP_ENV)


def on_cuda_unless(env: str) -> bool:
    """A choice that is on under a CUDA variant and off elsewhere, unless the environment variable ``env`` is
    ``1`` (on) or ``0`` (off): the render loop's overlap, moving shapes as instances (``scene/instancing.py``)."""
    choice = os.environ.get(env, "")
    if choice in ("0", "1"):
        return choice == "1"
    return mi.variant().startswith("cuda")
