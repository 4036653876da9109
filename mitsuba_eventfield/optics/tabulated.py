"""Scan curves given as tables over one period (``scan.TabulatedCurve``): the raster and the space-filling
Moore curve. ``scan.make_curve`` builds them by name."""
from __future__ import annotations

import math

import numpy as np

from ..errors import ConfigError
from ..validate import number
from .scan import DEFAULT_MAX_ANGLE_DEG, TabulatedCurve, _frac

# the counts of a tabulated scan and their ranges, and the most points its table may hold: 2 lines x
# samples_per_line (raster) or 4^order x samples_per_segment (moore); lines = 1e8 asked numpy for 95 GiB and
# said only that. Generous each (files written before the ranges must still read), bounded together.
COUNT_RANGES = {"lines": (1, 65536), "samples_per_line": (2, 65536), "order": (1, 8),
                "samples_per_segment": (1, 65536)}
MAX_TABLE_POINTS = 1 << 21          # the table is Python tuples: 2^24 points took 7.2 s and 2 GB, 2^21 ~1 s


def whole_counts(name: str, params: dict, where: str) -> dict:
    """``params`` of a ``name`` ("raster" or "moore") scan with its counts as ints within ``COUNT_RANGES`` and
    the table they make within ``MAX_TABLE_POINTS``; a fraction is refused (``lines=2.5`` became 2 lines)."""
    out = {k: int(number(v, f"{where}: {k}", *COUNT_RANGES[k], integer=True)) if k in COUNT_RANGES else v
           for k, v in params.items()}
    if name == "moore":
        points = 4 ** out.get("order", 3) * out.get("samples_per_segment", 8)
    else:
        points = 2 * out.get("lines", 8) * out.get("samples_per_line", 64)
    if points > MAX_TABLE_POINTS:
        raise ConfigError(f"{where}: {', '.join(f'{k} = {v}' for k, v in out.items() if k in COUNT_RANGES)}: "
                          f"a table of {points} points; at most {MAX_TABLE_POINTS} (fewer lines or samples)")
    return out


def raster(frequency=250.0, lines=8, amplitude_x=1.0, amplitude_y=1.0, samples_per_line=64,
           max_angle_deg=DEFAULT_MAX_ANGLE_DEG, galvo_model="ideal") -> TabulatedCurve:
    """x: triangle wave at ``frequency`` (a line each half period); y: a triangle over ``lines`` lines and back."""
    if not isinstance(lines, int) or lines < 1:
        raise ConfigError(f"scan: lines = {lines!r}: must be an integer >= 1")
    period = lines / frequency                       # `lines` half-periods of x down, `lines` back up
    n = 2 * lines * samples_per_line
    s = np.arange(n) / n
    tri = lambda u: 1.0 - 4.0 * np.abs(_frac(np, u + 0.25) - 0.5)  # noqa: E731  (range [-1, 1], starts at 0)
    x = math.radians(amplitude_x) * tri(s * lines)
    y = math.radians(amplitude_y) * tri(s)
    src = {"curve": "raster", "frequency": frequency, "lines": lines, "amplitude_x": amplitude_x,
           "amplitude_y": amplitude_y, "samples_per_line": samples_per_line}
    return TabulatedCurve(max_angle_deg=max_angle_deg, galvo_model=galvo_model, period_s=period, source=src,
                          _table=(tuple(x), tuple(y)), kind="raster")


def moore_vertices(order: int) -> np.ndarray:
    """Vertices of the closed Moore curve of ``order`` on the unit square [-1, 1]^2 (L-system)."""
    if not isinstance(order, int) or not 1 <= order <= 8:
        raise ConfigError(f"scan: order = {order!r}: the Moore curve order must be an integer in 1..8")
    axiom, rules = "LFL+F+LFL", {"L": "-RF+LFL+FR-", "R": "+LF-RFR-FL+"}
    s = axiom
    for _ in range(order - 1):
        s = "".join(rules.get(c, c) for c in s)
    pos, heading, pts = np.array([0, 0]), np.array([0, 1]), [np.array([0, 0])]
    for c in s:
        if c == "F":
            pos = pos + heading
            pts.append(pos)
        elif c == "+":
            heading = np.array([heading[1], -heading[0]])
        elif c == "-":
            heading = np.array([-heading[1], heading[0]])
    p = np.array(pts, dtype=np.float64)
    lo, hi = p.min(axis=0), p.max(axis=0)
    return 2 * (p - lo) / (hi - lo) - 1


def moore(frequency=10.0, order=3, amplitude=1.0, samples_per_segment=8,
          max_angle_deg=DEFAULT_MAX_ANGLE_DEG, galvo_model="ideal") -> TabulatedCurve:
    """Space-filling scan: the Moore curve of ``order`` over [-A, A]^2 degrees, once per 1/frequency seconds."""
    v = moore_vertices(order)
    closed = np.vstack([v, v[:1]])                   # the last vertex is adjacent to the first
    seg = np.linspace(0, 1, samples_per_segment, endpoint=False)
    pts = np.concatenate([a + (b - a) * seg[:, None] for a, b in zip(closed[:-1], closed[1:])])
    a = math.radians(amplitude)
    src = {"curve": "moore", "frequency": frequency, "order": order, "amplitude": amplitude,
           "samples_per_segment": samples_per_segment}
    return TabulatedCurve(max_angle_deg=max_angle_deg, galvo_model=galvo_model, period_s=1.0 / frequency,
                          source=src, _table=(tuple(a * pts[:, 0]), tuple(a * pts[:, 1])), kind="moore")
