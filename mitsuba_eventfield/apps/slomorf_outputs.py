"""Outputs of slow-motion refocus (a ``slomorf.SloMoRFResult``): frames, refocused images, video, GIF, figure,
metrics."""
from __future__ import annotations

import json
import math
import os
import time

import numpy as np

from ..errors import ConfigError


def to_display(linear: np.ndarray) -> np.ndarray:
    """How frames are shown and scored: radiance clipped to [0, 1], gamma 1/2.2, 8 bits."""
    return np.rint(np.clip(linear, 0.0, 1.0) ** (1 / 2.2) * 255).astype(np.uint8)


def write_outputs(result, out_dir: str, video_fps: float = 24.0, gif: bool = True) -> dict:
    """Frames (PNG), refocused frames (PNG), a video (MP4, and GIF), metrics.json and a summary figure, all
    written atomically with the run's metadata. Returns {kind: path(s)}."""
    import cv2
    from PIL import Image
    from PIL.PngImagePlugin import PngInfo

    from ..atomic import atomic_output, write_json
    t0 = time.perf_counter()
    os.makedirs(os.path.join(out_dir, "frames"), exist_ok=True)
    os.makedirs(os.path.join(out_dir, "refocus"), exist_ok=True)
    meta = {k: v for k, v in result.meta.items() if k != "time_split_s"}
    meta_json = json.dumps(meta, default=str)
    written = {"frames": [], "refocus": []}

    def png(path, img8, extra):
        info = PngInfo()
        info.add_text("eventfield_meta", json.dumps(dict(extra, **meta), default=str))
        with atomic_output(path, "image") as tmp:
            Image.fromarray(img8).save(tmp, format="PNG", pnginfo=info)
        return path

    films8 = to_display(result.frames["events"])
    rf8 = to_display(result.refocused["events"])
    for j, t in enumerate(result.times):
        kind = "rgb keyframe" if result.is_key[j] else "interpolated (events)"
        written["frames"].append(png(os.path.join(out_dir, "frames", f"frame_{j:04d}.png"), films8[j],
                                     {"time_s": float(t), "frame": kind}))
        for i, z in enumerate(result.depths):
            written["refocus"].append(png(os.path.join(out_dir, "refocus", f"depth_{z:g}_{j:04d}.png"), rf8[j, i],
                                          {"time_s": float(t), "frame": kind, "refocus_depth": z}))
    video = [_video_frame(rf8[j], result.depths, result.times[j], result.is_key[j]) for j in range(len(films8))]
    h, w = video[0].shape[:2]
    mp4 = os.path.join(out_dir, "slomorf.mp4")
    with atomic_output(mp4, "video") as tmp:
        writer = cv2.VideoWriter(tmp, cv2.VideoWriter_fourcc(*"mp4v"), float(video_fps), (w, h))
        if not writer.isOpened():
            raise ConfigError(f"{mp4}: OpenCV cannot write MP4 (mp4v) video here")
        for v in video:
            writer.write(np.ascontiguousarray(v[..., ::-1]))
        writer.release()
    written["mp4"] = mp4
    if gif:
        path = os.path.join(out_dir, "slomorf.gif")
        with atomic_output(path, "video") as tmp:
            imgs = [Image.fromarray(v) for v in video]
            imgs[0].save(tmp, format="GIF", save_all=True, append_images=imgs[1:], duration=int(1000 / video_fps),
                         loop=0, comment=meta_json.encode())
        written["gif"] = path
    written["figure"] = figure(result, os.path.join(out_dir, "slomorf.png"))
    result.meta["time_split_s"]["write"] = time.perf_counter() - t0
    written["metrics"] = write_json(os.path.join(out_dir, "metrics.json"),
                                    {"paper": paper_rows(result), "metrics": result.metrics, **result.meta})
    return written


# the paper's figure each bundled kaleidoscope scene reproduces, and what it claims (in our words)
PAPER = {"dart/kaleidoscope.xml": ("Fig. 9", "Kaleidoscope events interpolate seven frames between each pair of "
                                   "120 fps RGB frames (960 fps); the interpolated light field refocuses on the fast "
                                   "dart or on the background."),
         "falling/falling.xml": ("Fig. 8", "Kaleidoscope events and 120 fps RGB frames give a 6x faster (720 fps) "
                                 "colour light field that refocuses on each depth of a dynamic scene.")}


def paper_rows(result) -> list:
    """The metrics' "paper" row: the figure the scene reproduces (``PAPER``; Fig. 8 for other scenes), what it
    claims, and this run's numbers."""
    from .hdr import scene_argument
    m, meta = result.metrics, result.meta
    scene = meta["scene"].replace(os.sep, "/")
    fig, claim = next((v for k, v in PAPER.items() if scene.endswith("/" + k)), PAPER["falling/falling.xml"])
    f, r = m["frames"], m["refocus"]
    per_depth = ", ".join(f"{d['depth']:g} m {d['psnr']:.1f} vs {li['psnr']:.1f} dB"
                          for d, li in zip(r["events"]["per_depth"], r["linear"]["per_depth"]))
    focus = "yes" if m["focus_check"]["all_sharpest_at_own_depth"] else "no"
    cmd = f"eventfield slomorf {scene_argument(meta['scene'])}" + "".join(f" -D {k}={v}" for k, v in meta["defines"].items())
    cmd += (f" --fps {meta['fps']:g} --factor {meta['factor']} --duration {meta['duration_s']:.10g} --depths "
            + ",".join(f"{z:g}" for z in meta["depths"]))
    return [{"figure": fig, "claim": claim,
             "measured": f"{meta['factor']}x ({meta['output_fps']:g} fps from {meta['fps']:g} fps), "
             f"{m['interpolated_frames']} interpolated frames: PSNR {f['events']['psnr']:.1f} dB with events vs "
             f"{f['linear']['psnr']:.1f} dB for the linear blend of frames ({f['events']['psnr_moving']:.1f} vs "
             f"{f['linear']['psnr_moving']:.1f} dB on moving pixels); refocused {r['events']['psnr']:.1f} vs "
             f"{r['linear']['psnr']:.1f} dB ({per_depth}); each depth's pixels sharpest at their depth: {focus}.",
             "command": cmd,
             "differs": "The paper interpolates a real capture with TimeLens (learned warping) and aligns views by "
             "pattern matching. Here the interpolation is the model-free event method: a per-pixel luminance gain "
             "from the events, with colour from the keyframes. The views come from the kaleidoscope's geometry, and "
             "every score is against the renderer. Where an object moves by about its own size or more between "
             "two RGB frames, neither keyframe shows its colour at the new place, so only its luminance is right."}]


def _label(img8, text, scale=0.4):
    """A white strip with ``text`` above the image."""
    import cv2
    strip = np.full((16, img8.shape[1], 3), 255, np.uint8)
    cv2.putText(strip, text, (3, 12), cv2.FONT_HERSHEY_SIMPLEX, scale, (0, 0, 0), 1, cv2.LINE_AA)
    return np.concatenate([strip, img8], 0)


def _upscale(img8, min_size=160):
    k = max(1, int(math.ceil(min_size / img8.shape[0])))
    return np.repeat(np.repeat(img8, k, 0), k, 1)


def _row(images, gap=4):
    h = max(i.shape[0] for i in images)
    pad = [np.pad(i, ((0, h - i.shape[0]), (0, gap), (0, 0)), constant_values=255) for i in images]
    return np.concatenate(pad, 1)[:, :-gap]


def _stack(rows, gap=6):
    w = max(r.shape[1] for r in rows)
    pad = [np.pad(r, ((0, gap), (0, w - r.shape[1]), (0, 0)), constant_values=255) for r in rows]
    return np.concatenate(pad, 0)[:-gap]


def _video_frame(rf8_t, depths, t, is_key):
    tag = "RGB frame" if is_key else "interpolated"
    return _row([_label(_upscale(img), f"focus {z:g} | {t * 1e3:.2f} ms {tag}") for img, z in zip(rf8_t, depths)])


def figure(result, path: str) -> str:
    """Summary: the two RGB keyframes around the middle of the clip, the middle interpolated instant (truth,
    events, linear blend; centre view) and its refocus at every depth (events vs truth)."""
    from ..atomic import atomic_output
    from ..lightfield.views import extract_views
    factor = result.meta["factor"]
    key_idx = np.nonzero(result.is_key)[0]
    a = key_idx[max(0, len(key_idx) // 2 - 1)]
    b, j = a + factor, a + factor // 2
    optics = result.meta["optics"]
    centre = lambda name, i: to_display(extract_views(result.frames[name][i], optics).view(0, 0))  # noqa: E731
    key_a, key_b = centre("truth", a), centre("truth", b)
    mid = {k: centre(k, j) for k in ("truth", "events", "linear")}
    m = result.metrics
    ms = lambda i: f"{result.times[i] * 1e3:.2f} ms"  # noqa: E731
    row1 = _row([_label(_upscale(key_a), f"RGB frame {ms(a)}"), _label(_upscale(key_b), f"RGB frame {ms(b)}"),
                 _label(_upscale(mid["truth"]), f"truth {ms(j)}"),
                 _label(_upscale(mid["events"]), f"events: {m['frames']['events']['psnr_moving']:.1f} dB moving"),
                 _label(_upscale(mid["linear"]), f"linear: {m['frames']['linear']['psnr_moving']:.1f} dB moving")])
    rf = to_display(result.refocused["events"][j])
    rft = to_display(result.refocused["truth"][j])
    rfl = to_display(result.refocused["linear"][j])
    rows = [row1]
    for name, imgs in (("events", rf), ("truth", rft), ("linear", rfl)):
        rows.append(_row([_label(_upscale(img), f"{name}, focus {z:g} ({ms(j)})") for img, z in zip(imgs, result.depths)]))
    canvas = _stack(rows)
    from PIL import Image
    from PIL.PngImagePlugin import PngInfo
    info = PngInfo()
    info.add_text("eventfield_meta", json.dumps({k: v for k, v in result.meta.items()}, default=str))
    with atomic_output(path, "figure") as tmp:
        Image.fromarray(canvas).save(tmp, format="PNG", pnginfo=info)
    return path
