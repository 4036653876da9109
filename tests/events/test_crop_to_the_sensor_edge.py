"""A crop window may reach the sensor's last row and column: the window [x0, x0 + w) x [y0, y0 + h) lies inside
a W x H sensor exactly when x0 + w <= W and y0 + h <= H (pixel W - 1 is the last one). The whole sensor and a
10x10 window in its bottom-right corner are accepted, and cropping that corner keeps the events of pixel
(W - 1, H - 1); one pixel more is refused."""
import numpy as np
import pytest

import mitsuba_eventfield as ef
from mitsuba_eventfield.events.stream import EventStream
from mitsuba_eventfield.validate import crop_window

W, H = 64, 48


def test_windows_that_reach_the_last_pixel_are_inside():
    assert crop_window((0, 0, W, H), W, H) == (0, 0, W, H)
    assert crop_window((W - 10, H - 10, 10, 10), W, H) == (54, 38, 10, 10)
    for window in ((1, 0, W, H), (0, 0, W, H + 1), (W - 9, H - 10, 10, 10)):
        with pytest.raises(ef.ConfigError, match="must lie inside the 64x48 sensor"):
            crop_window(window, W, H)


def test_a_corner_crop_keeps_the_events_of_the_last_column_and_row():
    xs, ys = np.meshgrid(np.arange(W), np.arange(H))                 # one event at every pixel
    n = W * H
    ev = EventStream(xs.ravel(), ys.ravel(), np.arange(n), np.where(np.arange(n) % 2, 1, -1), W, H,
                     {"duration_us": n})
    cut = ev.crop(W - 10, H - 10, 10, 10)
    assert (cut.width, cut.height) == (10, 10) and len(cut) == 100
    assert np.array_equal(cut.counts(), np.ones((10, 10), np.int64))
    last = (cut.x == 9) & (cut.y == 9)
    assert np.count_nonzero(last) == 1 and cut.t[last][0] == n - 1       # the sensor's pixel (W - 1, H - 1)
    whole = ev.crop(0, 0, W, H)
    assert len(whole) == n and np.count_nonzero(whole.x == W - 1) == H
