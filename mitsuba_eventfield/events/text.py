"""E2VID text lines, ``t[s] x y p`` (seconds with six decimals, polarity 0 / 1), made by array operations.

``np.savetxt`` formats each value with a Python call: 2.4 us an event, so a 1280x720 render's 165 M events took
minutes of the writer thread, with the GIL held. Here every line of a block is laid out in one byte matrix (a
column per character, digits right-aligned in fields as wide as the block's largest value) and the characters a
line does not use (leading zeros, an absent sign) are dropped by one boolean selection, which keeps rows in
order. The text is that of ``"%.6f %d %d %d"`` on ``t * 1e-6``, except that the seconds come from the integer
microseconds (exact at any time; the float product rounds past about 10^9 s)."""
from __future__ import annotations

import numpy as np

BLOCK = 1 << 16          # events laid out at once: a few MB of temporaries
_ZERO = ord("0")


def _width(v: np.ndarray) -> int:
    return len(str(int(v.max())))


def _put_number(chars, kept, at: int, v: np.ndarray, width: int, pad: bool = False) -> None:
    """The non-negative integers ``v`` as ``width`` right-aligned ASCII digits in columns ``at`` onwards of
    ``chars`` (divmod by 10 a column, in 32 bits where they fit), their leading zeros left out of ``kept``
    unless ``pad``."""
    q = v.astype(np.uint32 if width <= 9 else np.uint64)
    for j in range(width - 1, -1, -1):
        q, digit = np.divmod(q, q.dtype.type(10))
        chars[:, at + j] = digit
        chars[:, at + j] += _ZERO
    if not pad:
        for j in range(width - 1):           # a zero is leading where the value has fewer digits than j's place
            kept[:, at + j] = v >= 10 ** (width - 1 - j)


def lines(t, x, y, p) -> bytes:
    """The text lines of events ``t`` (integer microseconds), ``x``, ``y``, ``p`` (> 0: ON), in their order."""
    t = np.asarray(t, np.int64)
    if len(t) == 0:
        return b""
    magnitude = np.abs(t)
    seconds, x, y = magnitude // 1_000_000, np.asarray(x, np.int64), np.asarray(y, np.int64)
    ws, wx, wy = _width(seconds), _width(x), _width(y)
    layout = [("-", 1), ("s", ws), (".", 1), ("us", 6), (" ", 1), ("x", wx), (" ", 1), ("y", wy), (" ", 1),
              ("p", 1), ("\n", 1)]
    at = dict(zip((k for k, _ in layout), np.cumsum([0] + [w for _, w in layout])))
    chars = np.empty((len(t), at["\n"] + 1), np.uint8)
    kept = np.ones(chars.shape, bool)
    for key in ("-", ".", " ", "\n"):
        chars[:, at[key]] = ord(key)
    chars[:, at["x"] - 1] = chars[:, at["y"] - 1] = ord(" ")
    kept[:, 0] = t < 0
    _put_number(chars, kept, at["s"], seconds, ws)
    _put_number(chars, kept, at["us"], magnitude % 1_000_000, 6, pad=True)
    _put_number(chars, kept, at["x"], x, wx)
    _put_number(chars, kept, at["y"], y, wy)
    chars[:, at["p"]] = _ZERO + (np.asarray(p) > 0)
    return chars[kept].tobytes()


def write_lines(f, t, x, y, p) -> None:
    """The lines of the events to the binary file ``f``, a block at a time."""
    for i in range(0, len(t), BLOCK):
        f.write(lines(t[i:i + BLOCK], x[i:i + BLOCK], y[i:i + BLOCK], p[i:i + BLOCK]))
