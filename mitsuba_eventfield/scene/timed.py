"""Scenes: any Mitsuba XML, plus rigid motion applied at each time step through ``mi.traverse``.

Mitsuba 3.9 has no animated transforms, so motion is a parameter update per step: ``<id>.to_world`` for
analytic shapes, instances and sensors, ``<id>.vertex_positions`` (and normals) for meshes. The new values are
opaque Dr.Jit variables, so the compiled render kernels are reused across steps (checked by a test through
Dr.Jit's kernel history). Keep moving meshes small: an update rebuilds the acceleration structure.
"""
from __future__ import annotations

import hashlib
import os
import re
from dataclasses import dataclass

import numpy as np

from .. import backend
from ..errors import EventFieldError, interrupt_in, plugin_message
from . import instancing
from . import sampler as sampler_module
from .motion import Motion, load_motion, motion_path_for, parse_motion

mi, dr = backend.mi, backend.dr


@dataclass
class _Binding:
    name: str
    key: str
    kind: str          # "to_world" or "vertices"
    base: object       # (transform type, its scalar type, float64 matrix at t=0, made opaque?), or
                       # (positions, normals) as Dr.Jit arrays


class TimedScene:
    """A loaded Mitsuba scene whose objects follow a :class:`~mitsuba_eventfield.motion.Motion` in time."""

    def __init__(self, scene, motion: Motion | None = None, path: str | None = None, instanced=()):
        if not isinstance(scene, mi.Scene):
            raise EventFieldError(f"TimedScene: scene must be a loaded mi.Scene (load_scene loads files), got "
                                  f"{type(scene).__name__}")
        if motion is not None and not isinstance(motion, Motion):
            raise EventFieldError(f"TimedScene: motion must be a Motion or None (load_motion / parse_motion make "
                                  f"one), got {type(motion).__name__}")
        if not scene.sensors():
            raise EventFieldError(f"{path or 'scene'}: the scene has no <sensor>: events need a camera")
        width, height = (int(v) for v in scene.sensors()[0].film().crop_size())
        if width < 1 or height < 1:       # a 0-pixel side divided by zero when the event batches were sized
            raise EventFieldError(f"{path or 'scene'}: film {width}x{height}: each side must be at least 1 pixel")
        self.scene = scene
        self.variant = mi.variant()        # what its objects belong to (load_scene switches back to it)
        self.motion = motion
        self.path = path
        self.defines: dict = {}   # the XML's <default> values given at load (-D): recorded, compared on resume
        self.instanced = list(instanced)   # moving shapes loaded as instances (scene/instancing.py)
        self.params = mi.traverse(scene)
        self.time = 0.0
        self.sampler_choice = "the scene's own"
        self._entry_base = None        # opaque UInt32 0 for the moving meshes' matrix gathers (_move_meshes)
        self._bindings = [self._bind(name) for name in (motion.objects if motion else {})]
        self._meshes = [b for b in self._bindings if b.kind == "vertices"]     # moved together, one kernel a step
        # time-varying sensors (the galvo) expose an opaque `time` parameter and reduce t to a scan phase
        self._sensor_times = [(key, node) for key, (_, _, node, _) in self.params.properties.items()
                              if key.endswith(".time") and hasattr(node, "phase_time")]
        self._moving = self._moving_params()

    def _moving_params(self):
        """The parameters a step writes, alone: Mitsuba's ``update()`` schedules and hashes every parameter it
        holds, in Python, on every backend, so the steps go through a copy kept to the moving ones (the same
        objects, parents notified the same way; the demo's step 0.378 -> 0.337 ms with 3 of its 40 parameters:
        docs/design.md). ``self.params`` keeps all of them for reading."""
        keys = [key for key, _ in self._sensor_times] + [b.key for b in self._bindings]
        keys += [b.name + ".vertex_normals" for b in self._meshes if b.base[1] is not None]
        moving = self.params.copy()
        moving.keep([re.escape(key) + "$" for key in keys] or ["$^"])
        return moving

    @property
    def scan_period(self) -> float | None:
        """Period of the view (the galvo scan); 0.0 for a time-invariant sensor; None if aperiodic."""
        periods = [node.period for _, node in self._sensor_times]
        if not periods:
            return 0.0
        if any(p is None for p in periods) or len(set(periods)) > 1:
            return None
        return periods[0]

    @property
    def is_static(self) -> bool:
        return self.motion is None or self.motion.is_static

    @property
    def sensor(self):
        return self.scene.sensors()[0]

    @property
    def film_size(self) -> tuple[int, int]:
        w, h = self.sensor.film().crop_size()
        return int(w), int(h)

    def movable_ids(self) -> list[str]:
        ids = set()
        for key in self.params.keys():
            for suffix in (".to_world", ".vertex_positions"):
                if key.endswith(suffix) and "." not in key[: -len(suffix)]:
                    ids.add(key[: -len(suffix)])
        return sorted(ids)

    def _bind(self, name: str) -> _Binding:
        keys = set(self.params.keys())
        if f"{name}.to_world" in keys:
            key = f"{name}.to_world"
            current = self.params[key]   # keep the t=0 placement as a float64 matrix: composing in NumPy
            scalar_type = getattr(mi, "Scalar" + type(current).__name__)     # its host (scalar) counterpart
            # a shape that emits keeps some of the transform's values as literals in its emitter's sampling,
            # which an unfrozen render would compile anew every step: its transform is made opaque (Mitsuba then
            # reads it back: tests/scene/test_motion.py)
            node = self.params.properties[key][2]
            opaque = isinstance(node, mi.Shape) and node.is_emitter()
            return _Binding(name, key, "to_world",
                            (type(current), scalar_type, np.array(current.matrix.numpy()).reshape(4, 4), opaque))
        if f"{name}.vertex_positions" in keys:
            key = f"{name}.vertex_positions"
            positions = mi.Point3f(dr.unravel(mi.Point3f, self.params[key]))
            nkey = f"{name}.vertex_normals"
            normals = None
            if nkey in keys and dr.width(self.params[nkey]) > 0:
                normals = mi.Normal3f(dr.unravel(mi.Normal3f, self.params[nkey]))
            dr.eval(positions, normals)
            return _Binding(name, key, "vertices", (positions, normals))
        src = self.motion.source if self.motion else "motion"
        raise EventFieldError(f"{src}: objects.{name}: the scene {self.path or ''} has no movable object with "
                              f"id '{name}' (movable ids: {', '.join(self.movable_ids()) or 'none'})")

    def set_time(self, t: float, view_time: float | None = None, apply: bool = True) -> None:
        """Move every object to its pose at time ``t`` (seconds); the view (a scanning sensor) to its phase at
        ``view_time`` when given (objects and view at different instants: ``static_pixels`` casts each pose
        from one scan phase), else at ``t``. ``apply=False`` stages the new values (traced, a moving mesh's
        kernel launched) and leaves Mitsuba's ``update()`` to :meth:`apply_time`: the render loop stages a step
        on a GPU while the device still renders the step before (``simulate/render.py``)."""
        self.time = float(t)
        if not self._bindings and not self._sensor_times:
            return
        for key, node in self._sensor_times:
            self._moving[key] = mi.Float(node.phase_time(self.time if view_time is None else float(view_time)))
        for b in self._bindings:
            if b.kind == "to_world":
                # built from a scalar (host) transform: its entries and inverse are literals, which Mitsuba
                # stores without reading anything back; one from a NumPy array copied 16 entries to the device
                # and Mitsuba read 28 back for its host-side copy, each a sync on a GPU (memsets instead: 15)
                transform_type, scalar_type, base, opaque = b.base
                xf = transform_type(scalar_type(self.motion.objects[b.name].matrix(self.time) @ base))
                if opaque:
                    dr.make_opaque(xf)
                self._moving[b.key] = xf
        if self._meshes:
            self._move_meshes(self._meshes)
        if apply:
            self._moving.update()

    def apply_time(self) -> None:
        """Mitsuba's ``update()`` of the values ``set_time(..., apply=False)`` staged: bounding boxes and
        acceleration structures rebuilt (on CUDA a moved mesh's box is read back, a sync)."""
        if self._bindings or self._sensor_times:
            self._moving.update()

    def _move_meshes(self, meshes) -> None:
        """Every moving mesh's positions and normals at ``self.time`` in one kernel, from one host-to-device copy
        of all their matrices (a Matrix4f per mesh from NumPy copied each of its 16 entries on its own)."""
        mats = np.stack([self.motion.objects[b.name].matrix(self.time) for b in meshes]).astype(np.float32)
        entries = mi.Float(mats.ravel())
        if self._entry_base is None:      # an opaque 0: matrix (opaque + i) is a gather inside the kernel; a
            self._entry_base = mi.UInt32(0)   # literal index would read each entry with a copy of its own
            dr.make_opaque(self._entry_base)
        moved = []                     # (parameter key, new vertex array) of every moving mesh
        for i, b in enumerate(meshes):
            xf = mi.Transform4f(dr.gather(mi.Matrix4f, entries, self._entry_base + i))   # the i-th row-major 4x4
            positions, normals = b.base
            moved.append((b.key, dr.ravel(xf @ positions)))
            if normals is not None:
                moved.append((b.name + ".vertex_normals", dr.ravel(dr.normalize(xf @ normals))))
        dr.eval(*(v for _, v in moved))   # every mesh's positions and normals in one kernel per step
        for key, value in moved:
            self._moving[key] = value

    def describe(self) -> dict:
        """Metadata describing the scene for output files."""
        d = {"scene_path": os.path.abspath(self.path) if self.path else None, "film": list(self.film_size),
             "sensor": type(self.sensor).__name__}
        if self.path and os.path.isfile(self.path):
            with open(self.path, "rb") as f:
                d["scene_sha256"] = hashlib.sha256(f.read()).hexdigest()
        if self.defines:
            d["defines"] = dict(sorted(self.defines.items()))
        if self.motion is not None:
            d["motion_path"] = self.motion.source
            d["motion"] = self.motion.raw
        if self.instanced:
            d["instanced"] = self.instanced
        return d


def _xml_value(value) -> str:
    """An XML default's text: a whole float as an integer (``width=64.0`` from arithmetic or NumPy; Mitsuba
    refused "64.0" for an integer parameter, and a float parameter reads "64" as well)."""
    if isinstance(value, (float, np.floating)) and float(value).is_integer():
        return str(int(value))
    return str(value.item() if isinstance(value, np.generic) else value)


def load_scene(scene, motion="auto", variant: str | None = None, color: bool = False, sampler: dict | None = None,
               **xml_params) -> TimedScene:
    """Load a Mitsuba XML scene (or wrap an ``mi.Scene``) with its motion.

    motion: "auto" (``<scene>.motion.toml`` next to the XML if it exists), None (static), a path, a dict
    (the TOML content) or a :class:`Motion`. ``xml_params`` fill the XML's ``<default name=...>`` values
    (e.g. ``width=64``). ``sampler``: the sensor's sampler (e.g. ``{"type": "multijitter", "sample_count": 16}``);
    None: the scene's own, or ``scene.sampler.DEFAULT_SAMPLER`` when it names none (``timed.sampler_choice``).
    """
    if isinstance(scene, TimedScene):
        # its Mitsuba objects belong to the variant it was loaded in: a colour scene loaded since then had
        # switched the process's variant, and rendering this one failed on a bare AssertionError in Mitsuba
        if scene.variant is not None and mi.variant() != scene.variant:
            backend.set_variant(scene.variant)
        return scene
    if variant is not None or color:
        backend.set_variant(variant, color)
    else:
        backend.ensure_variant()
    path = os.fspath(scene) if isinstance(scene, (str, os.PathLike)) else None
    if path is not None and not os.path.isfile(path):
        raise EventFieldError(f"{path}: scene file not found")
    if path is None and not isinstance(scene, mi.Scene):
        raise EventFieldError(f"load_scene: expected a path or mi.Scene, got {type(scene).__name__}")
    motion = _resolve_motion(motion, path)     # before the scene: which shapes move decides how it is loaded
    sampler_choice, instanced, text = "the scene's own", [], None
    if path is not None:
        xml_params = {k: _xml_value(v) for k, v in _film_override(path, xml_params).items()}
        try:
            with open(path) as f:
                original = f.read()
            text, sampler_choice = sampler_module.choose(original, sampler)
            if motion is not None and instancing.wanted():
                moving = [n for n, o in motion.objects.items() if not o.is_static]
                rewritten, instanced = instancing.rewrite(text or original, moving)
                text = rewritten or text
            scene = mi.load_file(path, **xml_params) if text is None else \
                sampler_module.load_text(mi, text, path, xml_params)
        except UnicodeDecodeError as e:   # (it has no strerror: reading it crashed the error message)
            raise EventFieldError(f"{path}: cannot read the scene: not UTF-8 text (byte {e.start}); save it as "
                                  "UTF-8") from None
        except OSError as e:
            raise EventFieldError(f"{path}: cannot read the scene ({e.strerror or type(e).__name__})") from None
        except Exception as e:  # Mitsuba reports XML/plugin errors as RuntimeError with a long trace
            # a Ctrl-C inside a plugin's constructor comes back as Mitsuba's error, the interrupt in its cause or
            # only in its text: a stop, not a bad scene (a generation loop catching EventFieldError went on)
            stop = interrupt_in(e)
            if stop is not None or "KeyboardInterrupt" in str(e):
                raise stop or KeyboardInterrupt() from e
            raise EventFieldError(f"{path}: {_load_error(e, path, original, text, xml_params)}") from None
    timed = TimedScene(scene, motion, path, instanced)
    timed.sampler_choice = sampler_choice
    timed.defines = dict(xml_params) if path is not None else {}
    return timed


def _resolve_motion(motion, path: str | None) -> Motion | None:
    if isinstance(motion, str) and motion == "auto":
        candidate = motion_path_for(path) if path else None
        return load_motion(candidate) if candidate and os.path.isfile(candidate) else None
    if isinstance(motion, (str, os.PathLike)):
        return load_motion(os.fspath(motion))
    if isinstance(motion, dict):
        return parse_motion(motion)
    if motion is not None and not isinstance(motion, Motion):
        raise EventFieldError(f"load_scene: motion = {motion!r}: expected 'auto', None, a motion file path, a dict "
                              "or a Motion")
    return motion


FILM_ENV = "EVENTFIELD_FILM"


def _film_override(path: str, xml_params: dict) -> dict:
    """``EVENTFIELD_FILM=WxH`` (the documented size for quick runs, e.g. the docs test): every scene file that
    declares ``width``/``height`` (or a square ``views_px`` film) defaults is loaded at that size instead,
    whatever the caller asked for."""
    import re
    spec = os.environ.get(FILM_ENV)
    if not spec:
        return xml_params
    size = re.fullmatch(r"\s*(\d+)\s*x\s*(\d+)\s*", spec)
    if not size or not (8 <= int(size[1]) <= 8192 and 8 <= int(size[2]) <= 8192):
        raise EventFieldError(f"{FILM_ENV} = {spec!r}: expected WIDTHxHEIGHT, each 8 to 8192 pixels")
    width, height = int(size[1]), int(size[2])
    with open(path) as f:
        declared = set(declared_defaults(f.read()))
    out = dict(xml_params)
    if {"width", "height"} <= declared:
        out.update(width=width, height=height)
    if "views_px" in declared:
        out["views_px"] = max(30, height - height % 6)     # n x n views of whole, even tiles
    return out


def _load_error(e: Exception, path: str, original: str, loaded: str | None, xml_params: dict) -> str:
    """The one-line message of a failed load, with the user's own line numbers: a rewritten text (a sampler
    chosen, moving shapes as instances) loses the file's comments and line breaks, so its error is looked up
    again by loading the file as it is, and taken where it is the same error at another place (a sampler the
    rewrite replaced may fail on its own; where the file loads, the rewritten text's message stays)."""
    unused = _unused_defines(e, original, xml_params)
    if unused:
        return unused
    message = _mitsuba_message(e)
    if loaded is not None:
        try:
            mi.load_file(path, **xml_params)
        except Exception as own:  # noqa: BLE001 (Mitsuba's loader errors are RuntimeErrors with long traces)
            place = re.compile(r"\(line \d+, col \d+\)")
            if place.sub("", _mitsuba_message(own)) == place.sub("", message):
                message = _mitsuba_message(own)
    return message


def declared_defaults(text: str) -> list:
    """The names of a scene XML's ``<default name=...>`` values."""
    import re
    return re.findall(r"<default\s[^>]*?name=[\"']([^\"']+)[\"']", text)


def settable_parameters(text: str) -> list:
    """What ``-D`` and a sweep's ``xml.*`` may set in a scene XML: its declared defaults, and any ``$name`` it
    uses without one (Mitsuba substitutes those too, and refuses a load that leaves one unset)."""
    import re
    names = declared_defaults(text)
    return names + [n for n in dict.fromkeys(re.findall(r"\$([A-Za-z_]\w*)", text)) if n not in names]


def _unused_defines(e: Exception, text: str, xml_params: dict) -> str | None:
    """Mitsuba's "Found unused parameters: - $widht=96" as the -D names the scene does not declare and the ones
    it does (its ``<default name=...>`` values); None for any other error."""
    import re
    if "Found unused parameters" not in str(e):
        return None
    declared = declared_defaults(text)
    unknown = [k for k in xml_params if k not in declared]
    return (f"scene value {', '.join(unknown) or ', '.join(xml_params)} (-D, or a keyword of load_scene): not a "
            f"value the scene declares; its <default> values are {', '.join(declared) or 'none'}")


def _mitsuba_message(e: Exception) -> str:
    """The informative part of a Mitsuba loader error, on one line.

    Mitsuba prefixes the XML location and, for a Python plugin, embeds the whole Python traceback; keep the
    location and the final exception line only.
    """
    import re
    raw = str(e)
    if "Traceback (most recent call last)" in raw:
        raw = raw.split("Traceback (most recent call last)")[0] + (plugin_message(e) or "")
    text = " ".join(raw.split())
    for marker in ("Error while loading", "Critical Dr.Jit compiler failure"):
        if marker in text:
            text = text[text.index(marker):]
    text = re.sub(r"\[[\w./]+\.cpp:\d+\]\s*", "", text)   # C++ source locations mean nothing to a user
    return text[:500]
