"""focus.measures.one_sided_texture against images whose answer is known: the texture a pixel's depth rests on
is the texture on its most uniform side, so a plain pixel beside an edge has none (the edge is no texture of
its own) and a linear ramp has none (defocus leaves it as it is)."""
import numpy as np
import pytest

from mitsuba_eventfield.errors import ConfigError
from mitsuba_eventfield.focus.measures import one_sided_texture

H, W, SIGMA = 40, 60, 0.2


def _noise(seed=0):
    return np.random.default_rng(seed).normal(0.0, SIGMA, (H, W))


def test_a_step_between_plain_halves_is_no_texture_on_either_side():
    img = np.where(np.arange(W) < 31, -1.0, 0.5)[None, :].repeat(H, 0)
    assert np.abs(one_sided_texture(img, 7)).max() < 1e-6


def test_a_linear_ramp_is_no_texture_up_to_the_border():
    y, x = np.mgrid[0:H, 0:W]
    assert np.abs(one_sided_texture(0.03 * x - 0.05 * y + 1.0, 7)).max() < 1e-5


def test_texture_reads_its_spread_about_the_local_plane():
    """White noise of standard deviation sigma: the least of four 7 x 7 squares' spread about their plane is
    below sigma and not far below (49 samples, 3 fitted)."""
    t = one_sided_texture(_noise(), 7)
    assert 0.5 * SIGMA < np.median(t) < SIGMA and t.min() > 0.3 * SIGMA


def test_a_plain_wall_beside_textured_card_has_none_of_its_texture():
    """The occluding edge of depth from focus: textured on the left (the card), plain on the right (the wall).
    Every wall pixel, the one next to the edge too, reads 0; every card pixel, the one next to the edge too,
    reads its texture. A symmetric measure (the log gradient) is as high on both sides of the edge."""
    edge = 31
    img = np.where(np.arange(W)[None, :] < edge, _noise(1), 1.5)
    t = one_sided_texture(img, 7)
    assert np.abs(t[:, edge:]).max() < 1e-6
    assert t[:, :edge].min() > 0.3 * SIGMA and np.median(t[:, edge - 1]) > 0.5 * SIGMA
    from mitsuba_eventfield.focus.measures import log_gradient
    assert np.median(log_gradient(img)[:, edge]) > np.median(log_gradient(img)[:, edge - 10])


@pytest.mark.parametrize("box", [0, 256, 2.5])
def test_the_box_is_checked(box):
    with pytest.raises(ConfigError, match="one_sided_texture: window"):
        one_sided_texture(_noise(), box)
