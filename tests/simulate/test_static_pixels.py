"""Static pixels under a periodic scan (simulate/static_pixels.py): the dynamic mask holds every pixel a moving
shape covers at the render's instants (Mitsuba's shape-index AOV at the true scan phase, an independent look);
reusing the static pixels gives exactly the events of rendering them at every step with the same samples; a
moving shadow the probes are not allowed to see makes the check warn, and the probes find it; the split is
declined, with a reason, when it cannot pay."""
import os

import numpy as np
import pytest

import mitsuba_eventfield as ef
from mitsuba_eventfield.scene.coverage import shape_masks
from mitsuba_eventfield.simulate import static_pixels as sp
from mitsuba_eventfield.simulate.pixel_setup import event_integrator
from mitsuba_eventfield.simulate.stepping import stepping

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
TEXT = os.path.join(ROOT, "scenes", "fan", "text.png")
W, H, PERIOD = 64, 48, 0.004
DURATION, STEPS = 4 * PERIOD, 4 * 20          # four 250 Hz scan periods, 20 steps each

# A ball crossing a galvo's view of a text wall. "emitting": the wall glows (its pixels are their own emission,
# so a wall pixel changes only when the ball covers it); "lit": a diffuse wall under a directional light from the
# side, so that the ball's shadow falls, and moves, well away from the ball's own image.
WALL = {
    "emitting": """<bsdf type="diffuse"><rgb name="reflectance" value="0"/></bsdf>
        <emitter type="area"><texture type="bitmap" name="radiance"><string name="filename" value="{text}"/>
        </texture></emitter>""",
    "lit": """<bsdf type="diffuse"><texture type="bitmap" name="reflectance"><string name="filename"
        value="{text}"/></texture></bsdf>""",
}
LIGHT = {"emitting": "", "lit": '<emitter type="directional"><vector name="direction" value="1, 0, 1"/>'
         '<rgb name="irradiance" value="3"/></emitter>'}
SCENE = """<?xml version="1.0"?>
<scene version="3.0.0">
    <integrator type="eventfield"><float name="threshold" value="0.2"/>
        <integrator type="path"><integer name="max_depth" value="2"/></integrator></integrator>
    <sensor type="galvo" id="camera">
        <float name="fov" value="45"/><float name="mirror_distance" value="0.1"/>
        <float name="mirror_separation" value="0.01"/><string name="curve" value="circle"/>
        <!-- 6 px of scan radius: more than the pose dilation -->
        <float name="frequency" value="250"/><float name="amplitude" value="2"/>
        <transform name="to_world"><lookat origin="0, 0, 0" target="0, 0, 1" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="{w}"/><integer name="height" value="{h}"/>
            <rfilter type="box"/></film>
    </sensor>
    {light}
    <shape type="rectangle" id="wall">
        <transform name="to_world"><scale x="1.2" y="0.9" z="1"/><rotate y="1" angle="180"/>
            <translate value="0, 0, 1.5"/></transform>
        {wall}
    </shape>
    <shape type="sphere" id="ball">
        <point name="center" value="-0.2, 0.05, 0.8"/><float name="radius" value="0.05"/>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.6"/></bsdf>
    </shape>
</scene>
"""


@pytest.fixture(autouse=True)
def few_periods_pay(monkeypatch):
    """The tests render four periods (tiny films): the split is taken from two on, as its logic allows."""
    monkeypatch.setattr(sp, "MIN_PERIODS", 2)


@pytest.fixture(scope="module")
def ball_scene(tmp_path_factory):
    folder = tmp_path_factory.mktemp("ball")
    paths = {}
    for kind in WALL:
        path = folder / f"ball_{kind}.xml"
        path.write_text(SCENE.format(w=W, h=H, light=LIGHT[kind], wall=WALL[kind].format(text=TEXT)))
        (folder / f"ball_{kind}.motion.toml").write_text("version = 1\n[objects.ball]\nvelocity = [10.0, 0, 0]\n")
        paths[kind] = str(path)
    return paths


def _plan(path):
    timed = ef.load_scene(path)
    st = stepping(timed, DURATION, STEPS, False, 0.5, None, None, 4, 0, "fixed", 0.0, 1.0)
    notes = []
    return timed, sp.plan(timed, st, event_integrator(timed, None, None, None, None), notes), notes


def test_the_dynamic_mask_holds_every_pixel_the_moving_ball_covers(ball_scene):
    timed, plan, _ = _plan(ball_scene["emitting"])
    assert plan is not None and 0.05 < plan.dynamic_share < 0.6
    covered = np.zeros((H, W), bool)
    for t in np.random.default_rng(3).uniform(0.0, DURATION, 40):    # objects and scan at the same instant
        ball = shape_masks(timed, float(t))["ball"]
        assert ball.any()
        assert not (ball & ~plan.dynamic).any(), f"ball pixels outside the dynamic mask at t = {t * 1e3:.3f} ms"
        covered |= ball
    # bounded, not everything: the mask is the ball's swept band (dilated), far from the whole frame
    assert plan.dynamic.sum() < 3 * covered.sum()


class _NeverCached(dict):
    def __contains__(self, key):       # every step renders its static pixels again, with the same samples
        return False


def test_reused_static_pixels_give_the_events_of_rendering_them_every_step(ball_scene, monkeypatch):
    timed = ef.load_scene(ball_scene["emitting"])
    reused = ef.render_events(timed, DURATION, steps=STEPS)
    meta = reused.meta["render"]["static_pixels"]
    assert meta is not None and meta["check_changed_share"] == 0.0
    assert reused.meta["render"]["render_s"] > 0
    original = sp.StaticPixels.__post_init__

    def never_cached(self):
        original(self)
        self.cache = _NeverCached()
    monkeypatch.setattr(sp.StaticPixels, "__post_init__", never_cached)
    rendered = ef.render_events(timed, DURATION, steps=STEPS)
    assert len(reused) > 1000
    for col in ("x", "y", "t", "p"):
        assert np.array_equal(getattr(reused, col), getattr(rendered, col))
    # and both are the scene's events: against rendering every pixel with Mitsuba's own render (other samples)
    full = ef.render_events(timed, DURATION, steps=STEPS, reuse=False)
    assert full.meta["render"]["static_pixels"] is None
    assert abs(len(reused) / len(full) - 1) < 0.03


def test_the_check_warns_when_a_moving_shadow_was_taken_as_static(ball_scene, monkeypatch):
    timed = ef.load_scene(ball_scene["lit"])
    probed = ef.render_events(timed, DURATION, steps=STEPS).meta["render"]
    assert probed["static_pixels"]["check_changed_share"] <= sp.CHECK_SHARE
    assert not any(n.startswith("warning") and "static" in n for n in probed["notes"])
    monkeypatch.setattr(sp, "_shadow_probes", lambda timed, st, times, covered, *a: np.zeros_like(covered))
    blind = ef.render_events(timed, DURATION, steps=STEPS).meta["render"]
    assert blind["static_pixels"]["check_changed_share"] > sp.CHECK_SHARE
    assert any(n.startswith("warning") and "taken as static" in n for n in blind["notes"])
    # the probes found the shadow's path: their mask holds more than the ball's own
    assert probed["static_pixels"]["dynamic_share"] > blind["static_pixels"]["dynamic_share"] + 0.05


def test_the_split_is_declined_when_it_cannot_pay(ball_scene, monkeypatch):
    timed = ef.load_scene(ball_scene["emitting"])
    st = stepping(timed, PERIOD, 20, False, 0.5, None, None, 4, 0, "fixed", 0.0, 1.0)
    integ = event_integrator(timed, None, None, None, None)
    assert sp.plan(timed, st, integ, []) is None                     # one period: nothing to reuse
    monkeypatch.setattr(sp, "MIN_PERIODS", 5)
    notes = []
    st = stepping(timed, DURATION, STEPS, False, 0.5, None, None, 4, 0, "fixed", 0.0, 1.0)
    assert sp.plan(timed, st, integ, notes) is None and "too few to pay" in notes[0]   # 4 periods < 5
    monkeypatch.setattr(sp, "MIN_PERIODS", 2)
    st = stepping(timed, DURATION, STEPS + 1, False, 0.5, None, None, 4, 0, "fixed", 0.0, 1.0)
    assert sp.plan(timed, st, integ, []) is None                     # steps off the scan's phase grid
    monkeypatch.setattr(sp, "MAX_DYNAMIC_SHARE", 0.01)
    timed, plan, notes = _plan(ball_scene["emitting"])
    assert plan is None and any("can change" in n for n in notes)


def test_the_command_line_says_so_and_no_reuse_turns_it_off(ball_scene, tmp_path, capsys):
    from mitsuba_eventfield.cli.main import main as cli
    for flags, expect in (([], True), (["--no-reuse"], False)):
        out = tmp_path / f"e{len(flags)}.h5"
        assert cli(["render", ball_scene["emitting"], "-o", str(out), "--duration", str(DURATION), "--steps",
                    str(STEPS), "--quiet"] + flags) == 0
        render = ef.read_events(str(out)).meta["render"]
        assert (render["static_pixels"] is not None) == expect
        assert ("static pixels reused" in capsys.readouterr().out) == expect


def test_the_frozen_coverage_is_the_traced_one(ball_scene):
    from mitsuba_eventfield.scene.coverage import covered_over_time
    timed = ef.load_scene(ball_scene["emitting"])
    times = np.linspace(0.0, DURATION, 9)
    frozen = covered_over_time(timed, times, ["ball"], view_time=0.001)
    traced = np.logical_or.reduce([shape_masks(timed, float(t), view_time=0.001)["ball"] for t in times])
    assert frozen.sum() > 50 and np.array_equal(frozen, traced)


def test_a_moving_instance_declines_the_split(ball_scene, tmp_path):
    """The ball as a Mitsuba instance: the shape-index AOV writes the index of the shapegroup's own shape, so
    the instance's mask is empty although the ball is in view, and a split from it would take the ball's pixels
    as static. ``coverage.unseen`` names it, and the split is declined with the reason."""
    from mitsuba_eventfield.scene.coverage import unseen
    text = open(ball_scene["lit"]).read()
    start, end = text.index('<shape type="sphere" id="ball">'), text.index("</scene>")
    ball = text[start:end].replace('id="ball"', 'id="ball_shape"')
    path = tmp_path / "ball_instance.xml"
    path.write_text(text[:start] + f'<shape type="shapegroup" id="ball_group">{ball}</shape>'
                    '<shape type="instance" id="ball"><ref id="ball_group"/></shape></scene>')
    (tmp_path / "ball_instance.motion.toml").write_text("version = 1\n[objects.ball]\nvelocity = [10.0, 0, 0]\n")
    timed, plan, notes = _plan(str(path))
    assert unseen(timed, ["ball", "wall", "camera"]) == ["ball", "camera"]
    import drjit as dr
    import mitsuba as mi
    from mitsuba_eventfield.scene.coverage import _aov
    timed.set_time(0.0)
    index = np.array(mi.render(timed.scene, integrator=_aov(), spp=1))[..., 0]
    ball = next(s for s in timed.scene.shapes() if s.id() == "ball")
    plain = shape_masks(ef.load_scene(ball_scene["lit"]), 0.0)
    # in view, yet no pixel carries the instance's own index; the masks leave it out
    own = float(dr.reinterpret_array(mi.UInt32, mi.ShapePtr(ball))[0])
    assert plain["ball"].sum() > 20 and not (index == own).any()
    assert "ball" not in shape_masks(timed, 0.0)
    assert plan is None and any("shape-index AOV" in n for n in notes), notes


def test_the_split_of_an_instanced_ball_is_the_meshes(ball_scene, monkeypatch):
    """The ball loaded as an instance by the package (scene/instancing.py, CUDA's default): the coverage finds
    it through its group's shape, so the split is made and its dynamic mask is that of the plain ball."""
    from mitsuba_eventfield.scene import instancing
    plans = {}
    for forced in ("0", "1"):
        monkeypatch.setenv(instancing.ENV, forced)
        timed, plans[forced], notes = _plan(ball_scene["lit"])
        assert timed.instanced == (["ball"] if forced == "1" else []) and plans[forced] is not None, notes
    plain, inst = plans["0"].dynamic, plans["1"].dynamic
    assert 0.01 < plain.mean() < 0.85 and (plain & inst).sum() >= 0.99 * (plain | inst).sum()
