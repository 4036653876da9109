"""``events.pairing``: the k-th event of a pixel and polarity against the k-th of the other stream, only where
the two counts agree, on streams built by hand."""
import numpy as np
import pytest

from mitsuba_eventfield.errors import ConfigError
from mitsuba_eventfield.events import EventStream
from mitsuba_eventfield.events.pairing import paired_time_differences, two_seed_timing_us


def _stream(rows, width=4, height=3):
    x, y, t, p = (np.array(c) for c in zip(*rows))
    return EventStream(x, y, t, p, width, height)


def test_kth_events_pair_by_pixel_and_polarity_where_counts_agree():
    a = _stream([(0, 0, 100, 1), (0, 0, 300, 1), (0, 0, 200, -1), (1, 2, 50, 1), (3, 1, 10, 1)])
    b = _stream([(0, 0, 130, 1), (0, 0, 290, 1), (1, 2, 40, 1), (1, 2, 60, 1), (3, 1, 70, -1), (0, 0, 260, -1)])
    r = paired_time_differences(a, b)
    # (0, 0) ON: 100/130 and 300/290; (0, 0) OFF: 200/260; (1, 2) ON counts 1 and 2: unpaired; (3, 1): polarities
    assert sorted(r["dt_us"].tolist()) == [10.0, 30.0, 60.0]
    assert r["share_a"] == pytest.approx(3 / 5) and r["share_b"] == pytest.approx(3 / 6)
    assert two_seed_timing_us(a, b) == pytest.approx(30.0 / np.sqrt(2))


def test_nothing_paired_and_other_sensors():
    a = _stream([(0, 0, 100, 1)])
    assert np.isnan(two_seed_timing_us(a, _stream([(1, 0, 100, 1)])))
    with pytest.raises(ConfigError, match="sensors differ"):
        paired_time_differences(a, _stream([(0, 0, 100, 1)], width=5))
