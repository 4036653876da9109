"""The analytic scene (``evaluation/analytic.py``: a sinusoidal emitter sliding past a pinhole, whose exact
events are known in closed form) as scene files any command renders and plans like a bundled scene, and the
scoring of a film of any even height against its exact events. Used by the speed-against-accuracy suite
(``bench.py``), ``--auto``'s tests and the default-steps tests."""
from __future__ import annotations

import math
import os

import numpy as np

from ..errors import ConfigError
from . import analytic as an

ANALYTIC_C, ANALYTIC_DURATION = 0.1, 0.01


ANALYTIC_XML = """<?xml version="1.0"?>
<!-- The analytic scene (evaluation/analytic.py): a sinusoidal emitter at z = {d} seen by a pinhole. -->
<scene version="3.0.0">
    <default name="height" value="{h}"/>  <!-- every row sees the same sinusoid: rows only add pixels -->
    <integrator type="eventfield">
        <float name="threshold" value="{c}"/>
        <integrator type="path"><integer name="max_depth" value="1"/></integrator>
    </integrator>
    <sensor type="perspective">
        <float name="fov" value="{fov}"/>
        <string name="fov_axis" value="x"/>
        <transform name="to_world"><lookat origin="0, 0, 0" target="0, 0, 1" up="0, 1, 0"/></transform>
        <film type="hdrfilm">
            <integer name="width" value="{w}"/>
            <integer name="height" value="$height"/>
            <rfilter type="box"/>
        </film>
    </sensor>
    <shape type="rectangle" id="plane">
        <transform name="to_world">
            <rotate y="1" angle="180"/>
            <scale x="{half}" y="{half}" z="1"/>
            <translate z="{d}"/>
        </transform>
        <emitter type="area">
            <texture type="bitmap" name="radiance">
                <string name="filename" value="analytic_texture.exr"/>
                <boolean name="raw" value="true"/>
                <string name="filter_type" value="bilinear"/>
                <string name="wrap_mode" value="clamp"/>
            </texture>
        </emitter>
    </shape>
</scene>
"""


def analytic_velocity(duration: float = ANALYTIC_DURATION, steps: int = 100) -> float:
    """Plane speed (world units per second) that moves the image half a pixel per step of ``steps``."""
    return 0.5 * an.PIX / (duration / steps)


def write_analytic_scene(folder: str, velocity: float, duration: float = ANALYTIC_DURATION,
                         threshold: float = ANALYTIC_C) -> str:
    """The analytic scene as files in ``folder`` (XML, its texture as EXR, its motion TOML), with Mitsuba's
    default sampler, so that it renders and plans like any scene file; returns the XML path. Its pixels are
    ``an.scene_dict``'s (same texture, geometry and film); ``-D height=N`` (even) adds rows, which see the same
    sinusoid (the plane faces the camera, so a column maps to one plane x) and are scored by
    :func:`analytic_score`."""
    import mitsuba as mi
    os.makedirs(folder, exist_ok=True)
    u = -1 + (np.arange(an.TEX_N) + 0.5) * (2 / an.TEX_N)
    tex = (an.A + an.B * np.sin(2 * np.pi * (-an.PLANE_HALF * u) / an.LAM)).astype(np.float32)
    mi.Bitmap(np.tile(tex, (2, 1))[..., None]).write(os.path.join(folder, "analytic_texture.exr"))
    path = os.path.join(folder, "analytic.xml")
    with open(path, "w") as f:
        f.write(ANALYTIC_XML.format(c=threshold, fov=repr(an.FOV), w=an.WIDTH, h=an.HEIGHT,
                                    half=repr(an.PLANE_HALF), d=repr(an.D)))
    with open(os.path.join(folder, "analytic.motion.toml"), "w") as f:
        f.write(f"version = 1\nduration = {duration!r}\n\n[objects.plane]\nvelocity = [{velocity!r}, 0.0, 0.0]\n")
    return path


def analytic_score(ev, truth) -> dict:
    """``an.score`` over a film of any even height: every pair of rows against the exact events of one pair."""
    from ..events.stream import EventStream
    if ev.width != an.WIDTH or ev.height % an.HEIGHT:
        raise ConfigError(f"analytic scene: a {ev.width}x{ev.height} film; expected {an.WIDTH} columns and an "
                          f"even number of rows")
    diffs, errors, y = [], [], ev.y.astype(np.int64)
    for row in range(0, ev.height, an.HEIGHT):
        sel = (y >= row) & (y < row + an.HEIGHT)
        s = an.score(EventStream(ev.x[sel], y[sel] - row, ev.t[sel], ev.p[sel], an.WIDTH, an.HEIGHT), truth)
        diffs.append(s["count_diff"])
        errors.append(s["timing_errors_us"])
    err = np.concatenate(errors)
    n_true = ev.height * sum(len(e) for e in truth)
    return {"count_error": float(np.abs(np.concatenate(diffs)).sum() / max(n_true, 1)),
            "timing_median_us": float(np.median(err)) if len(err) else math.nan,
            "timing_p99_us": float(np.percentile(err, 99)) if len(err) else math.nan}
