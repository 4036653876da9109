"""The render's event pixel: the scene's ``eventfield`` integrator (or one wrapping its radiance integrator),
configured from the scene's own settings, a preset and explicit values."""
from __future__ import annotations

from .. import backend
from ..errors import ConfigError
from ..scene.timed import TimedScene
from ..validate import MAX_THRESHOLD, number

mi = backend.mi


def event_integrator(timed: TimedScene, threshold, threshold_on, threshold_off, linlog_threshold, preset=None,
                      pixel=None, seed=None):
    """The scene's eventfield integrator (or one wrapping its radiance integrator), configured for this render:
    the scene's own pixel settings, then ``preset``, then explicit values (never an earlier render's; a bad
    ``threshold`` named as given, not as threshold_on). The pixel model's seed (its mismatch and noise draws) is
    the render's ``seed`` unless the pixel parameters or the scene's integrator name one: a sweep over seeds draws
    new sensor noise too (it kept pixel seed 0; 98 % of a davis346 render's noise events were the same)."""
    from ..plugins import pixel_model
    from ..plugins.event_integrator import integrator_class, is_event_integrator
    integ = timed.scene.integrator()
    if not is_event_integrator(integ):  # any scene: wrap its radiance integrator
        integ = integrator_class()(_props_with_inner(integ))
    if pixel is not None and not isinstance(pixel, dict):
        raise ConfigError(f"pixel model: pixel = {pixel!r}: must be a dict of pixel parameters (a preset's name "
                          "goes in preset=)")
    preset, pixel = pixel_model.preset_and_overrides(preset, pixel)
    thr = threshold if threshold is None else number(threshold, "render: threshold", 0, MAX_THRESHOLD, lo_open=True,
                                                           strict=True)
    overrides = {} if preset is not None else dict(integ.scene_overrides)
    explicit = dict(pixel_model.explicit_thresholds(thr, threshold_on, threshold_off),
                    linlog_threshold=linlog_threshold)
    pixel_model.given_once(explicit, pixel)
    explicit.update(pixel)
    for name, v in explicit.items():
        if v is not None:
            overrides[name] = v
    if seed is not None and overrides.get("seed") is None:
        overrides["seed"] = int(seed)
    integ.configure(pixel_model.pixel_config(preset or integ.scene_preset, "pixel model", **overrides))
    width, height = timed.film_size
    integ.config.check_film(width * height, f"{timed.path or 'scene'}: pixel model")   # before any work
    return integ


def _props_with_inner(inner):
    props = mi.Properties("eventfield")
    props["inner"] = inner
    return props
