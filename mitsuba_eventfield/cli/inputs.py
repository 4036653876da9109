"""What the commands that read event files share (``reconstruct``, ``refocus``, ``depth``, ``calibrate``): the
event file with its contrast thresholds and without its stuck pixels (``events.stuck_pixels``), a start frame, a
galvo period's frames, and the optics of a recording that carries none."""
from __future__ import annotations

import numpy as np

from ..errors import EventFieldError
from ..events.stuck_pixels import nonempty, without_stuck_pixels
from ..validate import MAX_THRESHOLD, number_list


def read_input(a, needs_optics: bool = False):
    """The event file of a command, with ``--contrast`` (when given) as its contrast thresholds; a stream that has
    none (a camera recording) and no ``--contrast`` is refused in one line, which also names the optics where
    the command ``needs_optics`` and the recording has none (it named one missing option a run)."""
    from ..events.io import read_events
    ev = cropped(read_events(a.file), a, a.file)
    if not len(ev):        # refocused, a flat image; as a depth map, no confident pixel: both written as done
        inside = f" inside the --crop window {a.crop}" if getattr(a, "crop", None) else ""
        raise EventFieldError(f"{a.file}: no events{inside}: nothing to reconstruct")
    try:
        kept = without_stuck_pixels(with_contrast(ev, getattr(a, "contrast", None), a.file), a.file)
    except EventFieldError as e:
        if needs_optics and not ev.meta.get("optics") and not (getattr(a, "optics", None)
                                                               or getattr(a, "calibration", None)):
            from ..calibration.recording import COMMAND_NAMES, optics_options
            raise EventFieldError(f"{e}; nor optics: pass {optics_options(COMMAND_NAMES)}") from None
        raise
    return nonempty(kept, a.file)


CROP_HELP = ("the window of the sensor that the kaleidoscope's tube image covers, x0,y0,width,height in pixels "
             "from the top-left (a camera recording on a larger sensor: its views are tiles of the window; frames of "
             "the whole sensor are cut to it)")


def crop_option(a, width: int, height: int):
    """``--crop X,Y,W,H`` checked against a ``width`` x ``height`` sensor; None when not given."""
    from ..validate import crop_window
    if not getattr(a, "crop", None):
        return None
    return crop_window(number_list(a.crop, "--crop"), width, height, "--crop")


def film_hint(e: Exception, window, width: int, height: int, where: str) -> str:
    """``e`` (a refusal of nominal optics on this film) with what the film is, where it is about the film: all
    of the frame or recording, or the ``--crop`` ``window`` (forgetting --crop on a larger sensor blamed the
    optics file's aspect ratio, and said nothing of --crop)."""
    import re
    if not re.search(r"\bfilm \d+x\d+", str(e)):      # a refusal of the film's size (aspect, views), no other
        return str(e)
    if window is not None:
        return f"{e} (the film: the --crop window {','.join(map(str, window))}, {width}x{height})"
    return (f"{e} (the film: all {width}x{height} of {where}; where the tube's image covers part of the sensor, "
            "pass --crop X,Y,W,H)")


def cropped(ev, a, where: str):
    """``ev`` cut to ``--crop`` (``EventStream.crop``, which refuses a stream with its own optics) when given."""
    if not getattr(a, "crop", None):
        return ev
    return ev.crop(*crop_option(a, ev.width, ev.height), where=f"--crop {a.crop}: {where}")


def with_contrast(ev, contrast, where: str):
    """``ev`` with ``--contrast`` (when given) as its contrast thresholds; a stream that has none (a camera
    recording) and no ``--contrast`` is refused in one line."""
    pm = ev.meta.get("pixel_model") or {}
    if contrast:
        c = number_list(contrast, "--contrast", lo=0, hi=MAX_THRESHOLD, lo_open=True)    # a render's threshold range
        if len(c) not in (1, 2):
            raise EventFieldError(f"--contrast {contrast!r}: expected ON or ON,OFF")
        if pm.get("threshold_on") is not None and pm.get("threshold_off") is not None:   # (as --optics is)
            raise EventFieldError(f"--contrast {contrast}: {where} carries its own contrast thresholds (ON "
                                  f"{pm['threshold_on']:g}, OFF {pm['threshold_off']:g}); --contrast is for a "
                                  "recording without them")
        ev.meta["pixel_model"] = pm = dict(pm, threshold_on=c[0], threshold_off=c[-1])
    if pm.get("threshold_on") is None or pm.get("threshold_off") is None:
        raise EventFieldError(f"{where}: the recording carries no contrast thresholds (pixel-model metadata): pass "
                              "--contrast ON[,OFF], log intensity per event (e.g. 0.2)")
    return ev


def luminance_channel(path, with_meta: bool = False):
    """The luminance of an EXR frame: its Y channel, or of its R, G, B (a colour camera's frame: its red channel
    alone was taken, and a depth from it read 3.9 % off against 1.8 %), or a single R; a named error without.
    ``with_meta``: (luminance, the metadata ``eventfield frame`` wrote: scene, time, spp, seed)."""
    from ..images import luminance, read_exr
    channels, meta = read_exr(path)
    if "Y" in channels:
        img = channels["Y"]
    elif all(c in channels for c in "RGB"):
        img = luminance(channels["R"], channels["G"], channels["B"])
    elif "R" in channels and not ({"G", "B"} & set(channels)):
        img = channels["R"]
    else:
        img = None
    if img is not None:
        return (img, meta) if with_meta else img
    raise EventFieldError(f"{path}: needs a Y channel, or R, G and B (linear, for their luminance); it has "
                          f"{', '.join(sorted(channels)) or 'none'}")


def start_log(path, events):
    """Log intensity (as the pixel sees it) of a linear EXR frame, checked against the stream's size."""
    from ..plugins.pixel_model import linlog_np, stream_linlog_threshold
    if path is None:
        return None
    img, meta = luminance_channel(path, with_meta=True)
    img = events.crop_frame(img, path)        # a frame of the whole sensor, cut as it was
    bad = int(np.count_nonzero(~np.isfinite(img)))
    if bad:                # (+inf became a level of +inf, and the frames' radiance inf)
        raise EventFieldError(f"{path}: {bad} pixels are not finite (inf or NaN): a start frame holds radiance")
    note = _other_samples(path, meta, events.meta)
    if note:                 # (a warning: the light-field commands hold it until their own checks have passed)
        import warnings
        warnings.warn(note, StartFrameWarning, stacklevel=2)
    return linlog_np(img, stream_linlog_threshold(events.meta))


class StartFrameWarning(UserWarning):
    """A rendered start frame whose samples are not the render's (``_other_samples``)."""


def _other_samples(path, frame_meta: dict, stream_meta: dict) -> str | None:
    """A rendered start frame (``eventfield frame``: spp, seed and sampler in its metadata) that is not the
    render's first image, said in one line; a camera's frame (no such metadata), or one that is: None. The events
    are changes from the pixels' own first image; a frame with other Monte-Carlo noise differs from it by up to
    whole log units (16 against 4 spp on the demo: 5.4), a fixed pattern in every view that pulls depth from
    focus toward the zero-shift plane (a scene author's 1.5 m plane read 1.34 m, 1.53 m with the render's own
    4 spp). No frame at one spp is the first image of a render that allocated samples (--spp-changing) or split
    off static pixels (a moving scene under a scan, by default from 40 periods)."""
    from ..scene.sampler import plugin_name
    from ..simulate.stepping import step_seed
    spp = frame_meta.get("spp")
    if spp is None or "spp" not in stream_meta:
        return None
    if stream_meta.get("sample_allocation"):
        return (f"{path}: the events had samples where they matter (--spp-changing): no frame of one spp is their "
                "first image; for an exact start frame render the events with --spp alone")
    if (stream_meta.get("render") or {}).get("static_pixels"):
        return (f"{path}: the events reused static pixels' frames (a moving scene under a scan): no frame is their "
                "first image; for an exact start frame render the events with --no-reuse")
    seed = stream_meta.get("seed", 0)
    if stream_meta.get("seed_mode", "fixed") != "fixed":            # the first image's seed (stepping)
        seed = step_seed(seed, 0)
    sampler = plugin_name((stream_meta.get("sampler") or {}).get("type", "")) or frame_meta.get("sampler")
    ours = (spp, frame_meta.get("seed", 0), frame_meta.get("sampler", sampler))      # (older frames: no sampler)
    if ours == (stream_meta["spp"], seed, sampler):
        return None
    return (f"{path}: rendered at {ours[0]} spp, seed {ours[1]}, {ours[2]} sampler; the events at "
            f"{stream_meta['spp']} spp, seed {seed}, {sampler} sampler: its noise is not the pixels' own first image "
            f"and stays in every view as a fixed pattern (depth leans toward the zero-shift plane); render it with "
            f"`eventfield frame --spp {stream_meta['spp']} --seed {seed}"
            + (f" --sampler {sampler}`" if ours[2] != sampler else "`"))


def galvo_scan(ev):
    """The scan curve of a galvo stream, or a one-line refusal of any other."""
    from ..optics.scan import curve_from_dict
    optics = ev.meta.get("optics", {})
    if optics.get("design") != "galvo":
        raise EventFieldError("not a galvo event stream (optics.design != 'galvo')" if optics else
                              "the stream carries no optics (a camera recording?): a galvo stream is needed")
    return curve_from_dict(optics["scan"])


def galvo_frames(ev, period, views, start_frame_log=None):
    """Reconstructed log frames and their times over one scan period of a galvo stream, and its scan curve."""
    from ..lightfield.model import galvo_period_starts, galvo_view_times
    from ..lightfield.reconstruct import reconstruct
    curve, optics = galvo_scan(ev), ev.meta["optics"]
    try:
        t0 = galvo_period_starts(ev, [period])[period]
    except ValueError as e:
        raise EventFieldError(f"--period: {e}") from None
    times = galvo_view_times(optics, t0, views)     # bin centres, as the light-field commands use
    method = "direct" if start_frame_log is not None else "galvo"
    kw = {"log_start": start_frame_log, "t_start": t0} if start_frame_log is not None else {"t_start": t0}
    return reconstruct(ev, times, method, **kw), times, curve


def reconstruct_optics(a, ev) -> tuple:
    """``reconstruct``'s stream with the optics its method reads, and the calibration parts applied (None: no
    calibration): ``--method galvo`` the scan (``--optics``) or a calibration's view phase and depth model,
    which enter its solve (``calibration.recording.calibrated_stream``); the other methods read none."""
    if a.calibration:
        from ..calibration import load_calibration
        from ..calibration.recording import calibrated_stream
        if a.method != "galvo":
            raise EventFieldError(f"--calibration {a.calibration}: for --method galvo (its view phase and depth "
                                  f"model enter the solve); --method {a.method} reads no optics")
        calibration = load_calibration(a.calibration)
        ev, _, applied = calibrated_stream(give_optics(ev, a.file, a.optics, calibration), calibration, a.file)
        return ev, applied
    if a.method == "galvo" or a.optics:
        ev = give_optics(ev, a.file, a.optics, takes_calibration=False)
    return ev, None


def give_optics(ev, where: str, optics_file: str | None, calibration=None, design: str | None = None,
                takes_calibration: bool = True):
    """``ev`` with the optics of a recording that carries none (``calibration.recording.with_optics``, as
    Python gives them, spelled as options): the set-up's nominal ones (``--optics``: any light-field design, or
    ``design``) or those of the calibration made for it (``--calibration``)."""
    from ..calibration.recording import COMMAND_NAMES, with_optics
    try:
        return with_optics(ev, optics_file, calibration, design=design, where=where, names=COMMAND_NAMES,
                           takes_calibration=takes_calibration)
    except EventFieldError as e:
        if optics_file is None or ev.meta.get("optics"):
            raise
        window = (ev.meta.get("crop") or {}).get("window")
        raise EventFieldError(film_hint(e, window, ev.width, ev.height, where)) from None
