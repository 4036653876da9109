"""Rigid motion of scene objects, declared in a small TOML file next to the scene XML.

File ``<scene>.motion.toml`` (found automatically next to ``<scene>.xml``)::

    version = 1
    duration = 0.05            # optional: default render duration in seconds

    [objects.ball]             # key = the `id` of a shape, instance or sensor in the XML
    velocity = [0.5, 0.0, 0.0] # constant linear velocity, scene units (metres) per second, world frame

    [objects.fan]
    spin = { rpm = 480, axis = [0, 0, 1], center = [0, 0, 2] }   # rotation about an axis through `center`

    [objects.dart]
    interpolation = "linear"   # "linear" (lerp + slerp), "cubic" (spline + rotation spline) or "step"
    pivot = [0, 0, 0]          # point the keyframe rotations turn about (default: world origin)
    keyframes = [              # poses relative to the XML placement; held constant outside [t_first, t_last]
      { t = 0.00, translate = [0, 0, 0], rotate = [0, 0, 0] },     # rotate: XYZ Euler angles in degrees
      { t = 0.05, translate = [0, 0, -1] },
    ]

Units: seconds, scene units, degrees, revolutions per minute (each number at most 1e9 in magnitude). Several
kinds may be combined on one object; the pose at time t maps the object's t=0 world placement to its placement
at t as ``Translate(velocity * t) @ Spin(t) @ Keyframes(t)`` (keyframes innermost, so a spinning object that
also moves spins about its own moving axis).
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field

import numpy as np

from ..errors import ConfigError
from ..validate import number, positive

try:
    import tomllib
except ImportError:  # Python < 3.11
    import tomli as tomllib

_TOP_KEYS = {"version", "duration", "objects"}
_OBJECT_KEYS = {"velocity", "spin", "keyframes", "interpolation", "pivot"}
_SPIN_KEYS = {"rpm", "axis", "center"}
_KEYFRAME_KEYS = {"t", "translate", "rotate"}
INTERPOLATIONS = ("linear", "cubic", "step")


@dataclass
class ObjectMotion:
    velocity: np.ndarray | None = None
    spin_rpm: float = 0.0
    spin_axis: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))
    spin_center: np.ndarray = field(default_factory=lambda: np.zeros(3))
    key_times: np.ndarray | None = None
    key_translations: np.ndarray | None = None
    key_rotations: object = None          # scipy Rotation with one entry per keyframe
    interpolation: str = "linear"
    pivot: np.ndarray = field(default_factory=lambda: np.zeros(3))
    _translation_spline: object = None
    _rotation_interp: object = None

    def __post_init__(self):
        if self.key_times is None:
            return
        from scipy.interpolate import CubicSpline
        from scipy.spatial.transform import RotationSpline, Slerp
        if len(self.key_times) >= 2:
            if self.interpolation == "cubic":
                self._translation_spline = CubicSpline(self.key_times, self.key_translations, axis=0)
                self._rotation_interp = RotationSpline(self.key_times, self.key_rotations)
            elif self.interpolation == "linear":
                self._rotation_interp = Slerp(self.key_times, self.key_rotations)

    @property
    def keys_move(self) -> bool:
        """The keyframes differ in pose (the object moves between them)."""
        return self.key_times is not None and bool(np.ptp(self.key_translations, axis=0).any() or len(
            self.key_times) > 1 and not np.allclose(self.key_rotations.as_quat(), self.key_rotations[0].as_quat()))

    @property
    def is_static(self) -> bool:
        return not (self.keys_move or self.spin_rpm != 0.0 or (self.velocity is not None and np.any(self.velocity)))

    def matrix(self, t: float) -> np.ndarray:
        """4x4 transform from the t=0 placement to the placement at time t (seconds)."""
        m = np.eye(4)
        if self.key_times is not None:
            m = self._keyframe_matrix(t)
        if self.spin_rpm:
            angle = 2.0 * math.pi * self.spin_rpm / 60.0 * t
            m = _about_point(_rotation_matrix(self.spin_axis, angle), self.spin_center) @ m
        if self.velocity is not None:
            shift = np.eye(4)
            shift[:3, 3] = self.velocity * t
            m = shift @ m
        return m

    def matrices(self, times) -> np.ndarray:
        """``matrix`` at every time of ``times``, (n, 4, 4): velocity and spin in closed form over the whole
        array (projecting a render's motion asks for hundreds of instants; one by one they cost ~25 us each)."""
        times = np.asarray(times, np.float64).ravel()
        if self.key_times is not None:
            m = np.stack([self._keyframe_matrix(float(t)) for t in times])
        else:
            m = np.tile(np.eye(4), (len(times), 1, 1))
        if self.spin_rpm:
            norm = float(np.linalg.norm(self.spin_axis))
            kx, ky, kz = self.spin_axis / norm
            k = np.array([[0.0, -kz, ky], [kz, 0.0, -kx], [-ky, kx, 0.0]])
            phi = (2.0 * math.pi * self.spin_rpm / 60.0 * norm) * times[:, None, None]
            spin = np.tile(np.eye(4), (len(times), 1, 1))
            spin[:, :3, :3] = np.eye(3) + np.sin(phi) * k + (1.0 - np.cos(phi)) * (k @ k)
            spin[:, :3, 3] = self.spin_center - spin[:, :3, :3] @ self.spin_center
            m = spin @ m
        if self.velocity is not None:
            m[:, :3, 3] += times[:, None] * self.velocity
        return m

    def _keyframe_matrix(self, t: float) -> np.ndarray:
        kt = self.key_times
        tc = min(max(t, kt[0]), kt[-1])
        if len(kt) == 1 or self.interpolation == "step":
            i = int(np.searchsorted(kt, tc, side="right") - 1)
            translation, rotation = self.key_translations[i], self.key_rotations[i].as_matrix()
        elif self.interpolation == "cubic":
            translation, rotation = self._translation_spline(tc), self._rotation_interp(tc).as_matrix()
        else:
            translation = np.array([np.interp(tc, kt, self.key_translations[:, j]) for j in range(3)])
            rotation = self._rotation_interp(tc).as_matrix()
        m = _about_point(rotation, self.pivot)
        m[:3, 3] += translation
        return m


@dataclass
class Motion:
    """Motion of every moving object of a scene, plus the file it came from."""
    objects: dict[str, ObjectMotion] = field(default_factory=dict)
    duration: float | None = None
    source: str | None = None
    raw: dict = field(default_factory=dict)

    def __post_init__(self):
        where = self.source or "Motion"
        if not isinstance(self.objects, dict) or not all(isinstance(o, ObjectMotion) for o in self.objects.values()):
            raise ConfigError(f"{where}: objects must map object ids to ObjectMotion (parse_motion builds them)")
        if self.duration is not None:
            self.duration = _positive(self.duration, where, "duration")

    @property
    def is_static(self) -> bool:
        return all(o.is_static for o in self.objects.values())

    def held_poses(self, t0: float, t1: float) -> list:
        """(object id, first keyframe time, last keyframe time) of each object whose keyframes move it and
        do not cover [t0, t1]: outside its keyframes such an object holds its first or last pose (its velocity
        and spin, if any, go on), which a render past them should say."""
        held = []
        for name, o in self.objects.items():
            if not o.keys_move:
                continue
            first, last = float(o.key_times[0]), float(o.key_times[-1])
            if t0 < first - 1e-12 or t1 > last + 1e-12:
                held.append((name, first, last))
        return held


class MotionHeldWarning(UserWarning):
    """A render runs outside an object's keyframes, where the object holds its first or last pose."""


def motion_path_for(scene_path: str) -> str:
    """Conventional motion-file path next to a scene: ``scene.xml`` -> ``scene.motion.toml``."""
    root, _ = os.path.splitext(scene_path)
    return root + ".motion.toml"


def load_motion(path: str) -> Motion:
    if not isinstance(path, (str, os.PathLike)):     # open(5) would read and close file descriptor 5
        raise ConfigError(f"load_motion: path = {path!r}: expected a motion file path (.motion.toml)")
    try:
        with open(path, "rb") as f:
            raw = tomllib.load(f)
    except FileNotFoundError:
        raise ConfigError(f"{path}: motion file not found") from None
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"{path}: not valid TOML: {e}") from None
    return parse_motion(raw, source=path)


def parse_motion(raw: dict, source: str = "<motion>") -> Motion:
    """Validate a motion description (the TOML as a dict); every error names the file and the key."""
    if not isinstance(raw, dict):
        raise ConfigError(f"{source}: motion must be a table (dict) with version, duration and [objects.<id>], "
                          f"got {type(raw).__name__}")
    _check_keys(raw, _TOP_KEYS, source, "")
    version = raw.get("version", 1)
    if version != 1:
        raise ConfigError(f"{source}: version = {version!r}: only version 1 is supported")
    duration = raw.get("duration")
    if duration is not None:
        duration = _positive(duration, source, "duration")
    objects = raw.get("objects", {})
    if not isinstance(objects, dict):
        raise ConfigError(f"{source}: objects must be a table of [objects.<id>] sections")
    parsed = {}
    for name, spec in objects.items():
        where = f"objects.{name}"
        if not isinstance(spec, dict):
            raise ConfigError(f"{source}: {where} must be a table")
        _check_keys(spec, _OBJECT_KEYS, source, where + ".")
        if not spec.keys() & {"velocity", "spin", "keyframes"}:
            raise ConfigError(f"{source}: {where} declares no motion (give velocity, spin or keyframes)")
        om = {}
        if "velocity" in spec:
            om["velocity"] = _vector(spec["velocity"], source, where + ".velocity")
        if "spin" in spec:
            spin = spec["spin"]
            if not isinstance(spin, dict):
                raise ConfigError(f"{source}: {where}.spin must be a table {{ rpm = ..., axis = [...], center = [...] }}")
            _check_keys(spin, _SPIN_KEYS, source, where + ".spin.")
            if "rpm" not in spin:
                raise ConfigError(f"{source}: {where}.spin.rpm is missing (revolutions per minute, any finite number)")
            om["spin_rpm"] = _finite(spin["rpm"], source, where + ".spin.rpm")
            axis = _vector(spin.get("axis", [0, 0, 1]), source, where + ".spin.axis")
            if np.linalg.norm(axis) == 0:
                raise ConfigError(f"{source}: {where}.spin.axis = {spin['axis']!r}: must be a non-zero vector")
            om["spin_axis"] = axis / np.linalg.norm(axis)
            om["spin_center"] = _vector(spin.get("center", [0, 0, 0]), source, where + ".spin.center")
        if "interpolation" in spec:
            if spec["interpolation"] not in INTERPOLATIONS:
                raise ConfigError(f"{source}: {where}.interpolation = {spec['interpolation']!r}: allowed values are "
                                  + ", ".join(repr(v) for v in INTERPOLATIONS))
            om["interpolation"] = spec["interpolation"]
        if "pivot" in spec:
            om["pivot"] = _vector(spec["pivot"], source, where + ".pivot")
        if "keyframes" in spec:
            om.update(_keyframes(spec["keyframes"], source, where + ".keyframes"))
        elif "interpolation" in spec or "pivot" in spec:
            raise ConfigError(f"{source}: {where}: interpolation/pivot need keyframes")
        parsed[name] = ObjectMotion(**om)
    return Motion(objects=parsed, duration=duration, source=source, raw=raw)


def _keyframes(frames, source, where):
    from scipy.spatial.transform import Rotation
    if not isinstance(frames, list) or not frames:
        raise ConfigError(f"{source}: {where} must be a non-empty array of {{ t = ..., translate = [...], "
                          "rotate = [...] }} tables")
    times, translations, eulers = [], [], []
    for i, kf in enumerate(frames):
        w = f"{where}[{i}]"
        if not isinstance(kf, dict):
            raise ConfigError(f"{source}: {w} must be a table {{ t = ..., translate = [...], rotate = [...] }}")
        _check_keys(kf, _KEYFRAME_KEYS, source, w + ".")
        if "t" not in kf:
            raise ConfigError(f"{source}: {w}.t is missing (time in seconds)")
        times.append(_finite(kf["t"], source, w + ".t"))
        translations.append(_vector(kf.get("translate", [0, 0, 0]), source, w + ".translate"))
        eulers.append(_vector(kf.get("rotate", [0, 0, 0]), source, w + ".rotate"))
    times = np.array(times)
    if np.any(np.diff(times) <= 0):
        raise ConfigError(f"{source}: {where}: keyframe times must be strictly increasing (got {times.tolist()})")
    return {"key_times": times, "key_translations": np.array(translations),
            "key_rotations": Rotation.from_euler("xyz", np.array(eulers), degrees=True)}


def _check_keys(table, allowed, source, prefix):
    unknown = sorted(set(table) - allowed)
    if unknown:
        raise ConfigError(f"{source}: unknown key {prefix}{unknown[0]}; allowed keys here: {', '.join(sorted(allowed))}")


# The largest magnitude a motion file's number may have (scene units, seconds, degrees, rpm): "any finite
# number" let 1e300 rpm reach math.sin as inf, and an axis of 1e300 overflow its norm (both exited with a
# traceback-less "unexpected" error), and a velocity of 1e30 asked for 1.4e29 steps. A billion is beyond any
# scene (a billion rpm turns a fan 16.7 million times a second) and keeps every product finite.
MAX_MOTION_VALUE = 1e9


def _finite(value, source, where):
    return number(value, f"{source}: {where}", -MAX_MOTION_VALUE, MAX_MOTION_VALUE, strict=True)


def _positive(value, source, where):
    return positive(value, f"{source}: {where}")


def _vector(value, source, where):
    if not isinstance(value, list) or len(value) != 3:
        raise ConfigError(f"{source}: {where} = {value!r}: must be an array of 3 finite numbers")
    return np.array([_finite(v, source, f"{where}[{i}]") for i, v in enumerate(value)])


def _rotation_matrix(axis, angle):
    """The rotation by the rotation vector ``axis * angle`` (Rodrigues' formula: SciPy's ``Rotation`` took
    0.1 ms a call, and a render asks for a spin's matrix several times a step)."""
    rotvec = np.asarray(axis, np.float64) * angle
    theta = math.sqrt(float(rotvec @ rotvec))
    if theta == 0.0:
        return np.eye(3)
    kx, ky, kz = rotvec / theta
    k = np.array([[0.0, -kz, ky], [kz, 0.0, -kx], [-ky, kx, 0.0]])
    return np.eye(3) + math.sin(theta) * k + (1.0 - math.cos(theta)) * (k @ k)


def _about_point(rotation3, point):
    m = np.eye(4)
    m[:3, :3] = rotation3
    m[:3, 3] = point - rotation3 @ point
    return m
