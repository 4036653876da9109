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


@pytest.mark.parametrize("box", [4, 7])
def test_a_linear_ramp_is_no_texture_up_to_the_border(box):
    y, x = np.mgrid[0:H, 0:W]
    assert np.abs(one_sided_texture(0.03 * x - 0.05 * y + 1.0, box)).max() < 1e-5


def test_texture_reads_its_spread_about_the_local_plane():
    """White noise of standard deviation sigma: the least of four 7 x 7 squares' spread about their plane is
    below sigma and not far below (49 samples, 3 fitted)."""
    t = one_sided_texture(_noise(), 7)
    assert 0.5 * SIGMA < np.median(t) < SIGMA and t.min() > 0.3 * SIGMA


@pytest.mark.parametrize("box", [3, 4, 6, 7])
@pytest.mark.parametrize("card_first", [True, False])
def test_a_plain_wall_beside_textured_card_has_none_of_its_texture(box, card_first):
    """The occluding edge of depth from focus: a textured card on one side, a plain wall on the other, across
    columns or rows. Every wall pixel, the one next to the edge too, reads 0; every card pixel, the one next to
    the edge too, reads its texture. A symmetric measure (the log gradient) is as high on both sides of the
    edge. Even boxes too (OpenCV centres an even box half a pixel off: a review found the wall reading 0.45
    with the card on one side and 0 with it on the other)."""
    edge = 31
    card = (np.arange(W) < edge) if card_first else (np.arange(W) >= edge)
    img = np.where(card[None, :], _noise(1), 1.5)
    for image, cards in ((img, card[None, :].repeat(H, 0)), (img.T, card[:, None].repeat(H, 1))):
        t = one_sided_texture(image, box)
        assert np.abs(t[~cards]).max() < 1e-6
        inner = np.zeros(cards.shape, bool)      # at the image's border a small box's squares are mostly mirror
        inner[box:-box, box:-box] = True
        assert t[cards & inner].min() > 0.2 * SIGMA
    from mitsuba_eventfield.focus.measures import log_gradient
    assert np.median(log_gradient(img)[:, edge]) > np.median(log_gradient(img)[:, 10 if card_first else 50])


@pytest.mark.parametrize("box", [0, 256, 2.5])
def test_the_box_is_checked(box):
    with pytest.raises(ConfigError, match="one_sided_texture: window"):
        one_sided_texture(_noise(), box)


def test_a_small_card_on_a_shaded_wall_leaves_the_wall_without_texture():
    """``depth.own_texture`` scales by the image's 90th percentile; where nine tenths of the image is a plain
    (shaded) wall that percentile is rounding noise, and without a floor 88 % of the wall passed (a review)."""
    from mitsuba_eventfield.focus.depth import OWN_TEXTURE_SHARE, own_texture
    y, x = np.mgrid[0:90, 0:120]
    img = 0.01 * x + 0.002 * y
    img[30:50, 40:60] += _noise(2)[:20, :20]
    share = own_texture([one_sided_texture(img, 7)], np.zeros(img.shape, int))
    card = np.zeros(img.shape, bool)
    card[30:50, 40:60] = True
    assert (share[~card] >= OWN_TEXTURE_SHARE).sum() == 0 and (share[card] >= OWN_TEXTURE_SHARE).mean() > 0.9
