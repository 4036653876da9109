"""E2VID text lines made by array operations (events/text.py) against ``np.savetxt``'s, which the writer used
before: the same bytes wherever the float seconds are exact, the exact seconds beyond."""
import io

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import mitsuba_eventfield as ef
from mitsuba_eventfield.events import text


def _savetxt(t, x, y, p) -> bytes:
    out = io.StringIO()
    np.savetxt(out, np.column_stack([np.asarray(t) * 1e-6, x, y, (np.asarray(p) > 0).astype(np.int64)]),
               fmt=["%.6f", "%d", "%d", "%d"])
    return out.getvalue().encode()


events = st.integers(1, 300).flatmap(lambda n: st.tuples(
    st.lists(st.integers(-(10 ** 12), 10 ** 12), min_size=n, max_size=n),
    st.lists(st.integers(0, 65535), min_size=n, max_size=n),
    st.lists(st.integers(0, 65535), min_size=n, max_size=n),
    st.lists(st.sampled_from([-1, 1]), min_size=n, max_size=n)))


@settings(max_examples=300, deadline=None)
@given(events)
def test_the_lines_are_savetxts_to_the_byte(columns):
    """Times of either sign up to 10^6 s (the float product t * 1e-6 is exact to the microsecond there),
    coordinates of 1 to 5 digits, zeros included."""
    t, x, y, p = (np.array(c, np.int64) for c in columns)
    assert text.lines(t, x, y, p) == _savetxt(t, x, y, p)


def test_field_edges_and_blocks():
    t = np.array([-1_500_000, -1, 0, 1, 999_999, 1_000_000, 9_999_999, 10_000_000])
    x, y, p = np.array([0, 9, 10, 99, 100, 65535, 1, 2]), np.zeros(8, int), np.array([1, -1] * 4)
    assert text.lines(t, x, y, p) == (b"-1.500000 0 0 1\n-0.000001 9 0 0\n0.000000 10 0 1\n0.000001 99 0 0\n"
                                      b"0.999999 100 0 1\n1.000000 65535 0 0\n9.999999 1 0 1\n10.000000 2 0 0\n")
    assert text.lines(t[:0], x[:0], y[:0], p[:0]) == b""
    n = 3 * text.BLOCK + 5                          # lines split into blocks: each block's own field widths
    rng = np.random.default_rng(1)
    t, x, y, p = np.sort(rng.integers(0, 10 ** 9, n)), rng.integers(0, 1280, n), rng.integers(0, 720, n), \
        rng.choice([-1, 1], n)
    x[:text.BLOCK] %= 10                            # a block of one-digit x beside blocks of four
    out = io.BytesIO()
    text.write_lines(out, t, x, y, p)
    assert out.getvalue() == _savetxt(t, x, y, p)


def test_seconds_stay_exact_where_the_float_product_rounds():
    """Past about 10^9 s the float t * 1e-6 loses the last microsecond; the integer seconds keep it."""
    t = np.array([2 ** 62 - 1])
    assert text.lines(t, [1], [2], [1]) == b"4611686018427.387903 1 2 1\n"
    assert _savetxt(t, [1], [2], [1]) != text.lines(t, [1], [2], [1])


@pytest.mark.parametrize("start", [0, -2_000_000])
def test_a_text_file_reads_back_the_same_events(tmp_path, start):
    n = 200_000
    rng = np.random.default_rng(2)
    ev = ef.EventStream(rng.integers(0, 346, n), rng.integers(0, 260, n), start + np.sort(rng.integers(0, 10 ** 7, n)),
                        rng.choice([-1, 1], n), 346, 260)
    path = str(tmp_path / "e.txt")
    ef.write_events(path, ev)
    back = ef.read_events(path)
    assert (back.width, back.height) == (346, 260)
    for k in "xytp":
        assert np.array_equal(getattr(back, k), getattr(ev, k)), k
