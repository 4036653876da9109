"""The high-pass and complementary reconstructions against their closed forms on hand-made events.

A first-order filter at cutoff f has impulse response exp(-2 pi f t), so from a still start the high-pass state
is sum_i w_i exp(-2 pi f (T - t_i)) over the events up to T (w = +C_on or -C_off), and the complementary state,
anchored to frame F_k from its time on, relaxes from the previous anchor by exp(-2 pi f (T - t_k)) and adds the
same decayed events. The rendered-scene test (test_lightfield.py) bounds their errors on a real stream; only
these closed forms tell a wrong decay rate, a wrong weight or a stale anchor apart from a right filter."""
import math

import numpy as np

import mitsuba_eventfield as ef
from mitsuba_eventfield.lightfield import reconstruct

C_ON, C_OFF, CUTOFF = 0.2, 0.3, 40.0
ALPHA = 2 * math.pi * CUTOFF


def _stream():
    """Two pixels of a 2x1 film: pixel 0 fires ON at 1, 2, 9 ms and OFF at 14 ms; pixel 1 OFF at 3 and 12 ms."""
    x = np.array([0, 0, 1, 0, 1, 0])
    t = np.array([1000, 2000, 3000, 9000, 12000, 14000])
    p = np.array([1, 1, -1, 1, -1, -1])
    return ef.EventStream(x, np.zeros(6, int), t, p, 2, 1, {"t_start_us": 0})


def _decayed_events(ev, pixel, until):
    sel = (ev.x == pixel) & (ev.t * 1e-6 <= until + 1e-12)
    w = np.where(ev.p[sel] > 0, C_ON, -C_OFF)
    return float(np.sum(w * np.exp(-ALPHA * (until - ev.t[sel] * 1e-6))))


def test_highpass_is_the_sum_of_decayed_events():
    ev = _stream()
    times = np.array([0.0005, 0.002, 0.0075, 0.012, 0.02])
    out = reconstruct.highpass(ev, times, cutoff_hz=CUTOFF, c_on=C_ON, c_off=C_OFF)
    expected = np.array([[[_decayed_events(ev, k, t) for k in (0, 1)]] for t in times])
    assert out.shape == (5, 1, 2)
    np.testing.assert_allclose(out, expected, rtol=1e-12, atol=1e-15)
    assert out[0].max() == 0 and out[2, 0, 0] > 0 > out[2, 0, 1]      # nothing yet; ON and OFF kept apart


def test_complementary_relaxes_towards_the_latest_frame():
    ev = _stream()
    frames = np.array([[[0.5, -1.0]], [[2.0, 0.0]]])      # log frames at 0 and 10 ms
    frame_times = np.array([0.0, 0.010])
    times = np.array([0.005, 0.010, 0.013, 0.030])
    out = reconstruct.complementary(ev, times, frames, frame_times, cutoff_hz=CUTOFF, c_on=C_ON, c_off=C_OFF)
    for k, t in enumerate(times):
        for pixel in (0, 1):
            if t < frame_times[1]:
                anchor = frames[0, 0, pixel]
            else:          # anchored to the second frame from its time on: the first one's offset decays away
                anchor = frames[1, 0, pixel] + (frames[0, 0, pixel] - frames[1, 0, pixel]) * \
                    math.exp(-ALPHA * (t - frame_times[1]))
            np.testing.assert_allclose(out[k, 0, pixel], anchor + _decayed_events(ev, pixel, t), rtol=1e-12,
                                       atol=1e-12)
    # 20 ms after the second frame (5 time constants of 4 ms) the state is that frame's, not the first one's
    assert abs(out[-1, 0, 0] - frames[1, 0, 0]) < 0.02 and abs(out[-1, 0, 0] - frames[0, 0, 0]) > 1


def test_events_at_the_start_instant_are_integrated():
    """A camera recording's stream starts at its first event (its reader has no other start): the direct and
    high-pass reconstructions dropped every event of that first microsecond (a kaleidoscope recording refocused
    differently from the same events with a render's metadata). An event at t_start came after the start image,
    and counts; one at a frame's time belongs to that frame."""
    x, t, p = np.array([0, 1, 0]), np.array([1000, 1000, 3000]), np.array([1, -1, 1])
    recording = ef.EventStream(x, np.zeros(3, int), t, p, 2, 1, {"t_start_us": 1000})
    direct = reconstruct.direct(recording, [0.001, 0.002, 0.003], c_on=C_ON, c_off=C_OFF)
    np.testing.assert_allclose(direct[:, 0], [[C_ON, -C_OFF], [C_ON, -C_OFF], [2 * C_ON, -C_OFF]], rtol=1e-12)
    high = reconstruct.highpass(recording, [0.001, 0.002], cutoff_hz=CUTOFF, c_on=C_ON, c_off=C_OFF)
    decay = math.exp(-ALPHA * 0.001)
    np.testing.assert_allclose(high[:, 0], [[C_ON, -C_OFF], [C_ON * decay, -C_OFF * decay]], rtol=1e-12)
    # from a given start (a prior that holds the events up to it, chained integration) they are not counted
    # twice; nor on top of a first frame at their time
    chained = reconstruct.direct(recording, [0.003], direct[0], t_start=0.001, c_on=C_ON, c_off=C_OFF)
    np.testing.assert_allclose(chained[0], direct[2], rtol=1e-12)
    anchored = reconstruct.complementary(recording, [0.001], frames=[np.zeros((1, 2))], frame_times=[0.001],
                                         cutoff_hz=CUTOFF, c_on=C_ON, c_off=C_OFF)
    assert np.all(anchored == 0)
