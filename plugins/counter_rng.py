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

The mixing function is MurmurHash3's 32-bit finaliser (a bijection with full avalanche): on the pixel (a Weyl
step), xored with the stream's word and hashed again, then xored with the counter's odd multiple and hashed a
third time. Every input enters through a nonlinear hash, never added to another one: where two inputs were
added (the pixel's Weyl step to the word until 2026-11-27; the pixel after hashing the counter before that),
two words or counters differing by a multiple of the Weyl step smaller than the film drew one row of pixels
shifted (odds of 2 x pixels / 2^32 a pair: about 100 pairs among a thousand seeds of a 1280x720 film, each
sharing up to all its noise events); xored after a hash, two rows coincide only pixel by pixel, at random.
Seeds and streams become words the same way (``hash_words``, ``stream_word``).
"""
from __future__ import annotations

import numpy as np

GOLDEN, M1, M2 = 0x9E3779B1, 0x85EBCA6B, 0xC2B2AE35     # Weyl step and MurmurHash3's finaliser
MASK = 0xFFFFFFFF
_SEED_MUL, _STREAM_MUL, _COUNTER_MUL = 0x27D4EB2F, 0x165667B1, 0x61C88647

# the streams of the pixel model: what a draw is for; the readout cap's keys are a stream of their own, whose
# steps are its sub-streams (``readout.step_word``: with the step as the stream number, the cap's steps 1-4
# drew the pixel model's four streams, key for draw)
JITTER_ON, JITTER_OFF, NOISE_WAIT, NOISE_POLARITY, READOUT = 1, 2, 3, 4, 5


def finalise(h):
    """MurmurHash3's finaliser on uint32 words: NumPy ``uint32`` arrays or Dr.Jit ``UInt32`` (both wrap), or a
    Python int (masked to 32 bits here)."""
    if isinstance(h, (int, np.integer)):         # (a NumPy integer would take the array path unwrapped)
        return _finalise_int(h)
    h = h ^ (h >> 16)
    h = h * M1
    h = h ^ (h >> 13)
    h = h * M2
    return h ^ (h >> 16)


def _finalise_int(h: int) -> int:
    h = int(h) & MASK
    h ^= h >> 16
    h = (h * M1) & MASK
    h ^= h >> 13
    h = (h * M2) & MASK
    return h ^ (h >> 16)


def mixed(index, word):
    """The hash of ``index`` (uint32 array) under ``word`` (one, or one an index): the draw ``index`` of the
    sequence ``word`` names. The index is hashed before the word enters: with ``finalise(index * GOLDEN +
    word)`` (until 2026-11-27) two words k Weyl steps apart drew one sequence shifted by k indices (seeds 0 and
    902: k = 806,330, an eighth of a 1280x720 sensor's noise events shared, pixel for shifted pixel)."""
    return finalise(finalise(index * GOLDEN) ^ word)


def mixed_np(index: np.ndarray, word) -> np.ndarray:
    """:func:`mixed` on NumPy arrays, without overflow warnings."""
    with np.errstate(over="ignore"):
        return mixed(np.asarray(index, dtype=np.uint32), np.uint32(word) if np.isscalar(word) else word)


def hash_words(*values: int) -> int:
    """One 32-bit word from integers >= 0 of any size (every bit used, 32 at a time, and how many): unrelated
    words for different inputs, where a sum (``seed + step``) made seed s at step k + 1 the seed s + 1 at
    step k, and a 32-bit cut made seed 2^32 the seed 0."""
    h = 7919
    for v in values:
        v = int(v)
        if v < 0:
            raise ValueError(f"hash_words: {v} is negative; seeds and counters are integers >= 0")
        chunks = 0
        while True:
            h = _finalise_int(h ^ _finalise_int((v & MASK) * _SEED_MUL + GOLDEN))
            v, chunks = v >> 32, chunks + 1
            if not v:
                break
        h = _finalise_int(h ^ chunks * _COUNTER_MUL)
    return h


def seed_word(seed: int) -> int:
    """The 32-bit word of a render's ``seed`` that every pixel-model draw is keyed by (a hash of all its bits:
    it was the seed's low 32 bits times a constant, so seeds 2^32 apart drew the same noise)."""
    return hash_words(seed)


def seed_array(mi, seed: int):
    """:func:`seed_word` as an opaque ``mi.UInt32`` of one entry: a kernel reads it as an input, so renders of
    different seeds share their kernels (and a frozen function's recordings)."""
    import drjit as dr
    return dr.opaque(mi.UInt32, seed_word(seed))


def stream_word(seed_word_, stream: int):
    """``seed_word_`` (int or UInt32) turned to the stream ``stream``: the draws of different streams of one
    seed are unrelated (a hash, not a sum: two seeds whose words differed by a stream step shared draws)."""
    return finalise(seed_word_ ^ _finalise_int(int(stream) * _STREAM_MUL + 1))


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
