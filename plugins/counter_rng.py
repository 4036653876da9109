"""Counter-based random numbers: every draw of the pixel model and the readout cap is a hash of what it is for
(seed, pixel, the pixel's own event counter, a stream number), not the next number of a generator's stream.

Why (2026-11-26): a per-pixel PCG32 stream had to be advanced every step whether or not a draw was used (else
its position, and every later draw, would depend on the events), so the realistic pixel paid five 64-bit
generator steps a pixel a step (0.14 ms at 346x260 on the CPU, 0.7x all of the ideal pixel's event kernels)
for draws that are used at a few percent of the pixel-steps. Keyed by the pixel's event counter, a draw is
made only where it is used, costs a few 32-bit integer operations, and is the same draw whatever the step
size: the thresholds held after a pixel's 17th event, or the wait before its 5th noise event, do not change
when a render takes twice the steps. (It did not make the model faster: inside the chunk kernels the draws
were not what the realistic pixel costs, docs/pixel_model.md; the invariance is what it buys.) The pixel
model draws in its step kernel, which both event paths share; the readout cap's keys are hashed on the host or
on the device (NumPy and Dr.Jit wrap uint32 the same way), so both paths draw the same keys without
exchanging any.

The mixing function is MurmurHash3's 32-bit finaliser (a bijection with full avalanche) applied twice: to the
pixel (a Weyl step) under the stream's word, then to that xor the counter's odd multiple. Not the pixel added
after hashing the counter: then the draws of two counters whose hashes differ by a multiple of the Weyl step
smaller than the film are one row of pixels shifted (odds of 2 x pixels / 2^32 a pair of counters: about 250
pairs among the first thousand counters of a 1280x720 film); xored after a nonlinear hash of the pixel, two
counters' rows coincide only pixel by pixel, at random.
"""
from __future__ import annotations

import numpy as np

GOLDEN, M1, M2 = 0x9E3779B1, 0x85EBCA6B, 0xC2B2AE35     # Weyl step and MurmurHash3's finaliser
MASK = 0xFFFFFFFF
_SEED_MUL, _STREAM_MUL, _COUNTER_MUL = 0x27D4EB2F, 0x165667B1, 0x61C88647

# the streams of the pixel model: what a draw is for
JITTER_ON, JITTER_OFF, NOISE_WAIT, NOISE_POLARITY = 1, 2, 3, 4


def finalise(h):
    """MurmurHash3's finaliser on uint32 words: NumPy ``uint32`` arrays or Dr.Jit ``UInt32`` (both wrap)."""
    h = h ^ (h >> 16)
    h = h * M1
    h = h ^ (h >> 13)
    h = h * M2
    return h ^ (h >> 16)


def mixed(index, word):
    """The hash of ``index`` (uint32 array) under ``word`` (one, or one an index): the draw ``index`` of the
    sequence ``word`` names."""
    return finalise(index * GOLDEN + word)


def mixed_np(index: np.ndarray, word) -> np.ndarray:
    """:func:`mixed` on NumPy arrays, without overflow warnings."""
    with np.errstate(over="ignore"):
        return mixed(np.asarray(index, dtype=np.uint32), np.uint32(word) if np.isscalar(word) else word)


def seed_word(seed: int) -> int:
    """The 32-bit word of a render's ``seed`` that every pixel-model draw is keyed by."""
    return (int(seed) * _SEED_MUL + 7919) & MASK


def seed_array(mi, seed: int):
    """:func:`seed_word` as an opaque ``mi.UInt32`` of one entry: a kernel reads it as an input, so renders of
    different seeds share their kernels (and a frozen function's recordings)."""
    import drjit as dr
    return dr.opaque(mi.UInt32, seed_word(seed))


def stream_word(seed_word_, stream: int):
    """``seed_word_`` (int or UInt32) turned to the stream ``stream``: the draws of different streams of one
    seed are unrelated."""
    return seed_word_ + (stream * _STREAM_MUL & MASK)


def bits(pixel, counter, word):
    """32 random bits for each ``pixel``'s draw number ``counter`` of the stream ``word`` (:func:`stream_word`);
    all uint32 (Dr.Jit ``UInt32`` or NumPy ``uint32``)."""
    return finalise(mixed(pixel, word) ^ (counter * _COUNTER_MUL))


def uniform(mi, pixel, counter, word):
    """A ``mi.Float`` uniform in [0, 1) (24 bits) for each pixel's draw ``counter`` of the stream ``word``."""
    return mi.Float(bits(pixel, counter, word) >> 8) * (1.0 / (1 << 24))


def draw(mi, pixel, counter, seed_word_, stream: int):
    """:func:`uniform` of the pixel model's ``stream`` (``JITTER_ON``, ...) under a render's ``seed_word_``."""
    return uniform(mi, pixel, counter, stream_word(seed_word_, stream))
