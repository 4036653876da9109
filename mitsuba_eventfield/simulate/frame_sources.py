"""Frames a user already has, as a stream of (time in seconds, linear intensity) for the frames-to-events
converter: a NumPy array, an ``.npz`` stack, a folder of images, or a video (through OpenCV). Frames are read
one at a time, so a long video never sits in memory.

Intensity: integer pixels are scaled to [0, 1] by their type's maximum (8 and 16 bit), floating-point ones
(EXR, float arrays) are taken as linear radiance. Colour becomes luminance (Rec. 709 weights, as Mitsuba's
``luminance``). Video and ordinary images are gamma-encoded: ``srgb=True`` decodes them to linear light first,
which is what a photoreceptor sees; the default leaves values as they are (the convention of v2e and ESIM).
"""
from __future__ import annotations

import contextlib
import os
import re
from dataclasses import dataclass
from typing import Iterator

import numpy as np

from ..images import LUMA
from ..errors import EventFieldError
from ..validate import available_memory
from .frame_times import (  # noqa: F401  (check_span, read_times: re-exported)
    check_span, check_times, one_clock, read_times, times_mismatch, times_of, uniform_rate)

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".exr", ".pgm", ".ppm")
VIDEO_SUFFIXES = (".mp4", ".avi", ".mov", ".mkv", ".webm", ".m4v", ".mpg", ".mpeg")


@dataclass
class FrameSource:
    """A sequence of frames: ``count`` (None when a video does not say), size, and ``frames()`` yielding
    (t seconds, float32 (H, W) linear intensity)."""
    name: str
    width: int
    height: int
    count: int | None
    frames: object          # () -> Iterator[tuple[float, np.ndarray]]
    describe: dict
    device: bool = False    # frames() yields flat float arrays of the active Dr.Jit backend instead (from_device)
    # (first, count) -> frames first .. first + count - 1 as one flat array of the backend, where the source
    # holds them in one buffer (from_device): a group of frames is then one gather, not one kernel a frame
    block: object = None
    times: object = None    # the frames' times in seconds where known before reading them (with ``block``)
    span_s: float | None = None     # last frame's time minus the first's, where known before reading them
    start_s: float | None = None    # the first frame's time, where known before reading it


def srgb_to_linear(v: np.ndarray) -> np.ndarray:
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4).astype(np.float32)


def intensity(frame: np.ndarray, srgb: bool = False, bgr: bool = False, where: str = "frame") -> np.ndarray:
    """One frame (H, W), (H, W, 1), (H, W, 3) or (H, W, 4) as float32 linear luminance."""
    a = np.asarray(frame)
    if a.ndim == 3 and a.shape[2] in (1, 3, 4):
        pass
    elif a.ndim != 2:
        raise EventFieldError(f"{where}: shape {a.shape}: expected (H, W) or (H, W, 1|3|4)")
    if a.dtype in (np.uint8, np.uint16):
        v = a.astype(np.float32) / np.float32(np.iinfo(a.dtype).max)
    elif np.issubdtype(a.dtype, np.integer):
        # scaled by its type's maximum, an int64 array (NumPy's default integer) of 8-bit values made no events
        raise EventFieldError(f"{where}: pixel type {a.dtype}: integer frames must be uint8 or uint16 (scaled by "
                              "their maximum); give other values as floats (linear intensity)")
    elif np.issubdtype(a.dtype, np.floating):
        v = a.astype(np.float32)
    else:
        raise EventFieldError(f"{where}: pixel type {a.dtype}: expected uint8, uint16 or floats")
    if not np.isfinite(v).all() or (v < 0).any():
        raise EventFieldError(f"{where}: intensities must be finite and >= 0")
    if srgb:
        v = srgb_to_linear(v)
    if v.ndim == 3:
        if v.shape[2] == 1:
            v = v[..., 0]
        else:
            rgb = v[..., 2::-1] if bgr else v[..., :3]      # OpenCV reads BGR(A)
            v = rgb @ LUMA
    return np.ascontiguousarray(v, np.float32)


def from_array(frames, times=None, fps=None, srgb=False, where="frames") -> FrameSource:
    """An in-memory stack (T, H, W[, C]) with times in seconds (or a frame rate)."""
    try:
        a = np.asarray(frames)
    except ValueError:       # a list of frames of different sizes
        raise EventFieldError(f"{where}: the frames differ in size (a stack needs one size)") from None
    if a.ndim not in (3, 4) or a.shape[0] < 2 or 0 in a.shape[1:3]:
        raise EventFieldError(f"{where}: shape {a.shape}: expected (T, H, W) or (T, H, W, C) with T >= 2, H, W >= 1")
    one_clock(times, fps, where)
    t = check_times(times, a.shape[0], where) if times is not None else \
        np.arange(a.shape[0]) / uniform_rate(fps, where)

    def frames_iter():
        for i in range(a.shape[0]):
            yield float(t[i]), intensity(a[i], srgb, where=f"{where}[{i}]")
    return FrameSource(where, a.shape[2], a.shape[1], a.shape[0], frames_iter, {"kind": "array"},
                       span_s=float(t[-1] - t[0]), start_s=float(t[0]))


def is_device_array(frames) -> bool:
    """A Dr.Jit array or tensor, or another library's array that hands its memory over through DLPack (a
    PyTorch or CuPy tensor): frames for :func:`from_device`. NumPy arrays and lists stay on the host path."""
    import drjit as dr
    return dr.is_array_v(frames) or (hasattr(frames, "__dlpack__") and not isinstance(frames, np.ndarray))


def from_device(frames, times=None, fps=None, srgb=False, where="frames") -> FrameSource:
    """A (T, H, W) stack of linear float intensities already where the active Dr.Jit backend computes: a
    Dr.Jit tensor, or a PyTorch / CuPy array taken through DLPack. Checked there (finite and >= 0: one
    reduction) and handed on as flat device arrays, a frame or a group of consecutive frames at a time
    (``block``: a gather at an opaque offset, one cached kernel whatever the offset), never copied to the host.
    Colour, integer and sRGB frames take the host path (``from_array``), whose conversions they need."""
    import drjit as dr
    import mitsuba as mi
    if srgb:           # one decoding, srgb_to_linear's: a second one on the device would round otherwise
        raise EventFieldError(f"{where}: srgb: device frames must be linear already (decode them first, or pass "
                              "a NumPy array, which srgb=True decodes)")
    kind = str(getattr(frames, "dtype", "float32"))
    if "float" not in kind.lower():
        raise EventFieldError(f"{where}: device frames of type {kind}: expected floats (linear intensity)")
    try:
        tensor = frames if isinstance(frames, mi.TensorXf) else mi.TensorXf(frames)
    except Exception as e:          # whatever the conversion raises: one line
        raise EventFieldError(f"{where}: not an array the {mi.variant()} backend takes "
                              f"({' '.join(str(e).split())[:100] or type(e).__name__})") from None
    shape = tuple(tensor.shape)
    if len(shape) != 3 or shape[0] < 2 or 0 in shape[1:]:
        raise EventFieldError(f"{where}: shape {shape}: device frames must be (T, H, W) with T >= 2, H, W >= 1")
    one_clock(times, fps, where)
    t = check_times(times, shape[0], where) if times is not None else np.arange(shape[0]) / uniform_rate(fps, where)
    flat = tensor.array
    if bool(dr.any(~dr.isfinite(flat) | (flat < 0))[0]):
        raise EventFieldError(f"{where}: intensities must be finite and >= 0")
    n = shape[1] * shape[2]

    def block(first: int, count: int):
        offset = mi.UInt32(first * n)
        dr.make_opaque(offset)          # one cached kernel whatever the offset
        return dr.gather(mi.Float, flat, dr.arange(mi.UInt32, count * n) + offset)

    def frames_iter():
        for i in range(shape[0]):
            yield float(t[i]), block(i, 1)
    return FrameSource(where, shape[2], shape[1], shape[0], frames_iter, {"kind": "device array"}, device=True,
                       block=block, times=t, span_s=float(t[-1] - t[0]), start_s=float(t[0]))


def from_npz(path: str, fps=None, srgb=False, times=None) -> FrameSource:
    """An ``.npz`` with ``frames`` (T, H, W[, C]) and ``times`` (seconds) or ``timestamps_us``; a stack without
    either takes ``times`` (seconds) or ``fps``."""
    try:
        data = np.load(path, allow_pickle=False)
    except Exception as e:            # empty (EOFError), not a zip, damaged: one line whatever NumPy raises
        raise EventFieldError(f"{path}: not a readable .npz ({' '.join(str(e).split())[:100] or type(e).__name__})") \
            from None
    if "frames" not in data:
        raise EventFieldError(f"{path}: no 'frames' array (found: {', '.join(data.files) or 'nothing'})")
    times_key = next((k for k in ("times", "timestamps_us") if k in data), None)
    if "times" in data and "timestamps_us" in data:         # one would be ignored (it was: 'timestamps_us')
        raise EventFieldError(f"{path}: both 'times' (seconds) and 'timestamps_us' are given: keep one")
    if times_key and (fps is not None or times is not None):
        given = f"fps = {fps!r}" if fps is not None else "times given"
        raise EventFieldError(f"{path}: {given}: this stack carries its own times ('{times_key}'); give times or "
                              "a frame rate only for stacks without them, image folders and videos")
    given_times = times
    try:     # the members are read here, not by np.load: a damaged or pickled one fails now
        frames = data["frames"]
        times = given_times if times_key is None else data[times_key]
    except MemoryError:              # a valid stack larger than the memory left: not a damaged file
        size = data.zip.getinfo("frames.npy").file_size if "frames.npy" in data.zip.namelist() else 0
        raise EventFieldError(f"{path}: its frames ({size / 2**20:.0f} MiB) do not fit in the memory available "
                              f"({available_memory() / 2**20:.0f} MiB); convert a folder of images or a video, "
                              "which are read frame by frame") from None
    except Exception as e:
        raise EventFieldError(f"{path}: not a readable .npz ({' '.join(str(e).split())[:100] or type(e).__name__})") \
            from None
    if times_key == "timestamps_us":
        times = check_times(times, None, path, name="timestamps_us", unit="microseconds") * 1e-6
    src = from_array(frames, times, fps, srgb, where=path)
    src.describe = {"kind": "npz", "path": os.path.abspath(path)}
    return src


def _natural_key(name: str):
    return [int(part) if part.isdigit() else part.lower() for part in re.split(r"(\d+)", name)]


def _read_image(path: str) -> np.ndarray:
    import cv2
    if path.lower().endswith(".exr"):
        from ..images import read_exr
        channels, _ = read_exr(path)
        if "Y" in channels:
            return channels["Y"]
        if all(c in channels for c in "RGB"):
            return np.stack([channels[c] for c in "BGR"], axis=-1)   # as OpenCV would give it
        raise EventFieldError(f"{path}: EXR without Y or R, G, B channels")
    img = cv2.imread(path, cv2.IMREAD_UNCHANGED)
    if img is None:
        raise EventFieldError(f"{path}: cannot read this image")
    return img


def from_folder(path: str, fps=None, srgb=False, times=None) -> FrameSource:
    """Every image of a folder in natural name order (frame_2 before frame_10), at ``times`` (seconds, one an
    image in that order) or ``fps``."""
    names = sorted((n for n in os.listdir(path) if n.lower().endswith(IMAGE_SUFFIXES)), key=_natural_key)
    if len(names) < 2:
        raise EventFieldError(f"{path}: {len(names)} images ({', '.join(IMAGE_SUFFIXES)}); need at least 2")
    one_clock(times, fps, path)
    time_of, span = times_of(times, len(names), fps, path)
    first = intensity(_read_image(os.path.join(path, names[0])), srgb, bgr=True, where=names[0])
    h, w = first.shape

    def frames_iter():
        for i, name in enumerate(names):
            f = os.path.join(path, name)
            img = intensity(_read_image(f), srgb, bgr=True, where=f)
            if img.shape != (h, w):
                raise EventFieldError(f"{f}: size {img.shape[1]}x{img.shape[0]}, the first image is {w}x{h}")
            yield time_of(i), img
    return FrameSource(path, w, h, len(names), frames_iter,
                       {"kind": "image folder", "path": os.path.abspath(path), "fps": fps,
                        "times": "given" if times is not None else "from the frame rate"}, span_s=span,
                       start_s=time_of(0))


# containers whose frame count OpenCV reads from the file (FFmpeg's nb_frames): a video that ends before it is
# cut or damaged. Matroska / WebM counts are estimated from duration x rate (one frame of slack); MPEG program
# streams' estimates were off by 29 of 30 frames (an under-count: nothing to check against).
VIDEO_COUNT_SLACK = {".avi": 0, ".mp4": 0, ".mov": 0, ".m4v": 0, ".mkv": 1, ".webm": 1}
FFMPEG_LOGLEVEL_ENV = "OPENCV_FFMPEG_LOGLEVEL"


@contextlib.contextmanager
def _quiet_opencv():
    """OpenCV's and FFmpeg's own lines kept off the terminal while a video is opened or read: a damaged file
    made them print lines of raw bytes before the one-line error. FFmpeg takes its log level once per process,
    from ``OPENCV_FFMPEG_LOGLEVEL`` at its first use (too late where the process used OpenCV's video I/O
    before), and OpenCV's AVI parser writes to the file descriptor directly, so standard error's descriptor
    points at the null device meanwhile (this thread only writes there in between: a progress bar's lines
    stay)."""
    import sys

    import cv2
    os.environ.setdefault(FFMPEG_LOGLEVEL_ENV, "-8")        # AV_LOG_QUIET, where FFmpeg has not started yet
    level = cv2.utils.logging.getLogLevel()
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_ERROR)
    sys.stderr.flush()
    saved, null = os.dup(2), os.open(os.devnull, os.O_WRONLY)
    os.dup2(null, 2)
    try:
        yield cv2
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(null)
        cv2.utils.logging.setLogLevel(level)


def _open_video(path: str):
    """An opened ``cv2.VideoCapture`` (FFmpeg's reader where OpenCV was built with it, else whichever it
    has), or None."""
    with _quiet_opencv() as cv2:
        backend = cv2.CAP_FFMPEG if cv2.videoio_registry.hasBackend(cv2.CAP_FFMPEG) else cv2.CAP_ANY
        cap = cv2.VideoCapture(path, backend)
        if cap.isOpened():
            return cap
        cap.release()
    return None


def from_video(path: str, fps=None, srgb=False, times=None) -> FrameSource:
    """A video through OpenCV; frame times from ``times`` (seconds, one a frame) or ``fps`` when given, else from
    the container's frame rate. A video that ends before the frame count its container states is refused as cut
    or damaged (one line, and the conversion's output file is not written), not converted in part."""
    import cv2
    cap = _open_video(path)
    if cap is None:
        raise EventFieldError(f"{path}: OpenCV cannot open this video")
    rate = fps if fps is not None else cap.get(cv2.CAP_PROP_FPS)
    count = max(0, int(cap.get(cv2.CAP_PROP_FRAME_COUNT))) or None
    w, h = int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
    cap.release()
    one_clock(times, fps, path)
    slack = VIDEO_COUNT_SLACK.get(os.path.splitext(path)[1].lower())
    # given times are checked against the container's count where it is exact, else frame by frame
    time_of, span = times_of(times, count if slack == 0 else None, None, path) if times is not None else \
        times_of(None, count, rate if rate and rate > 0 else None, path)

    def frames_iter() -> Iterator[tuple[float, np.ndarray]]:
        video = _open_video(path)
        if video is None:
            raise EventFieldError(f"{path}: OpenCV cannot open this video")
        try:
            i = 0
            while True:
                with _quiet_opencv():
                    ok, img = video.read()
                if not ok:
                    if count and slack is not None and i < count - slack:
                        raise EventFieldError(f"{path}: frame {i + 1} of {count} unreadable (the video is cut or "
                                              "damaged): nothing written")
                    if times is not None and i != len(times):
                        raise EventFieldError(times_mismatch(path, len(times), i))
                    return
                yield time_of(i), intensity(img, srgb, bgr=True, where=f"{path} frame {i}")
                i += 1
        finally:
            video.release()
    return FrameSource(path, w, h, count, frames_iter, {"kind": "video", "path": os.path.abspath(path),
                                                         "fps": float(rate) if times is None else None,
                                                         "times": "given" if times is not None else "from the frame rate"},
                       span_s=span, start_s=time_of(0))


def open_frames(path: str, fps=None, srgb=False, times=None) -> FrameSource:
    """The right reader for ``path``: a folder of images, an ``.npz`` stack or a video file; ``times``: the
    frames' times in seconds instead of a frame rate."""
    if os.path.isdir(path):
        return from_folder(path, fps, srgb, times)
    if not os.path.exists(path):
        raise EventFieldError(f"{path}: no such file or folder")
    suffix = os.path.splitext(path)[1].lower()
    if suffix == ".npz":
        return from_npz(path, fps, srgb, times)
    if suffix in VIDEO_SUFFIXES:
        return from_video(path, fps, srgb, times)
    raise EventFieldError(f"{path}: unknown input type {suffix or '(none)'}: expected a folder of images, "
                          f"an .npz stack or a video ({', '.join(VIDEO_SUFFIXES)})")
