"""What a chunk's kernels read of an event integrator besides its pixel state: the pixel model and the per-pixel
constants, in the form a Dr.Jit frozen function takes (``event_batch``'s chunk passes)."""
from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import mitsuba as mi


@dataclass
class PixelView:
    """What a chunk's kernels read of an integrator besides its state: the pixel model (``config``, a key) and
    the per-pixel constants (thresholds, reference anchor, leak rates) and the draws' seed word, as arrays a
    frozen function takes as arguments (:meth:`arrays`, :meth:`bind`); the same names as the integrator's, so
    ``pixel_step.step`` reads either."""
    config: object
    linlog_threshold: float
    c_on: object = None
    c_off: object = None
    anchor: object = None
    leak_rate: object = None
    seed_word: object = None

    CONSTANTS = ("c_on", "c_off", "anchor", "leak_rate", "seed_word")
    PER_PIXEL = ("c_on", "c_off", "anchor", "leak_rate")      # the seed word is one number for every pixel

    @staticmethod
    def of(integ) -> "PixelView":
        return PixelView(integ.config, integ.linlog_threshold, integ.c_on, integ.c_off, integ.anchor,
                         integ.leak_rate, integ.seed_word)

    # configuration fields no chunk pass reads (the seed draws the per-pixel constants and keys the draws
    # through the seed word, which are arguments): left out of the key, so a sweep over seeds replays one
    # recording
    UNTRACED = ("seed",)

    def key(self) -> tuple:
        """The model, as a frozen function's key: every value its kernels bake in. From the configuration's
        own fields (numbers and the preset's name), not ``as_dict``, whose deep copies cost 0.08 ms a key."""
        return (tuple(sorted((k, v) for k, v in vars(self.config).items() if k not in self.UNTRACED)),
                self.linlog_threshold, tuple(getattr(self, k) is not None for k in self.CONSTANTS), mi.variant())

    def model(self) -> "PixelView":
        """The model alone, without arrays (what a cached frozen pass may keep)."""
        return PixelView(self.config, self.linlog_threshold)

    def arrays(self) -> dict:
        return {k: getattr(self, k) for k in self.CONSTANTS if getattr(self, k) is not None}

    def bind(self, arrays: dict) -> "PixelView":
        return PixelView(self.config, self.linlog_threshold, **{k: arrays.get(k) for k in self.CONSTANTS})

    def gather(self, idx) -> "PixelView":
        """The view at pixels ``idx``."""
        return PixelView(self.config, self.linlog_threshold, seed_word=self.seed_word,
                         **{k: (dr.gather(type(v), v, idx) if v is not None else None)
                            for k, v in ((k, getattr(self, k)) for k in self.PER_PIXEL)})
