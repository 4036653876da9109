"""The ideal event pixel, as pure functions the integrator and the tests share.

An event fires each time the pixel's log brightness ``L`` moves by a contrast threshold from its reference
level; the reference then moves by exactly one threshold (so several events can fire in one step, and no
residual is lost). Between two rendered instants ``L`` is taken as linear in time, which fixes the timestamp of
every crossing (the ESIM model).

Dr.Jit side (per pixel, dense): :func:`linlog`, :func:`count_crossings`.
NumPy side (sparse, only pixels that fired): :func:`expand_crossings` turns the per-pixel counts into events.
"""
from __future__ import annotations

import math

import numpy as np

from mitsuba_eventfield.errors import ConfigError   # a ValueError too: one named error for bad pixel input
from mitsuba_eventfield.plugins.event_memory import check_event_count
from mitsuba_eventfield.plugins.readout import READOUT_BINS_PER_MS
from mitsuba_eventfield.validate import MAX_THRESHOLD


def linlog(dr, intensity, linear_below: float):
    """Log brightness with a linear segment below ``linear_below`` (C1-continuous), so zero radiance is finite.

    For I >= I_l: log(I); below: log(I_l) + (I - I_l) / I_l, the tangent of log at I_l. Real photoreceptors
    behave alike (dark current), and it keeps Monte-Carlo zeros from producing -inf.
    """
    il = float(linear_below)
    return dr.select(intensity >= il, dr.log(dr.maximum(intensity, il)), math.log(il) + (intensity - il) / il)


def linlog_inverse(dr, log_brightness, linear_below: float):
    """Radiance from lin-log brightness (the inverse of :func:`linlog`)."""
    il = float(linear_below)
    lil = math.log(il)
    return dr.select(log_brightness >= lil, dr.exp(log_brightness), il * (1.0 + log_brightness - lil))


def linlog_np(intensity, linear_below: float):
    """NumPy twin of :func:`linlog` (used by oracles and offline tools)."""
    i = np.asarray(intensity, dtype=np.float64)
    il = float(linear_below)
    return np.where(i >= il, np.log(np.maximum(i, il)), math.log(il) + (i - il) / il)


def linlog_inverse_np(level, linear_below: float):
    """NumPy twin of :func:`linlog_inverse`: radiance of lin-log levels (a reconstruction's, on a start frame
    taken through :func:`linlog_np`); below the knee plain ``exp`` is not the inverse (a level of zero radiance
    came back 0.37 of the knee's radiance high)."""
    level = np.asarray(level, dtype=np.float64)
    il = float(linear_below)
    knee = math.log(il)
    return np.where(level >= knee, np.exp(np.maximum(level, knee)), il * (1.0 + level - knee))


def film_readout_cap(cap: float, native_pixels, n_pix: int) -> float:
    """A readout cap (events/s) on a film of ``n_pix`` pixels: scaled by film / native pixels where the sensor's
    native pixel count is given (truthy), so a small film saturates like the whole sensor; else as it is."""
    return cap * (n_pix / native_pixels if native_pixels else 1)


DEFAULT_LINLOG_THRESHOLD = 1e-3      # radiance below which the response is linear (``PixelConfig``'s default)


def stream_linlog_threshold(meta: dict) -> float:
    """The lin-log knee of the pixel that made a stream (its metadata), the default one for a stream without it
    (a camera recording)."""
    return float((meta.get("pixel_model") or {}).get("linlog_threshold", DEFAULT_LINLOG_THRESHOLD))


# crossings a pixel may count in one step: far above any real step's (a log range of ~100 over the smallest
# threshold), and below 2^31, so the Int32 count cannot wrap (1e10 became INT_MIN, a negative count that the
# event-count guard then had to catch by accident: ``check_event_count`` refuses such a step)
MAX_CROSSINGS = float(1 << 30)


def count_crossings(dr, Int, log_now, log_ref, c_on, c_off):
    """Signed number of threshold crossings per pixel: n > 0 means n ON events (L rose by n*c_on from the
    reference), n < 0 means |n| OFF events; at most ``MAX_CROSSINGS`` either way."""
    rise = log_now - log_ref
    n_on = dr.minimum(dr.maximum(dr.floor(rise / c_on), 0.0), MAX_CROSSINGS)
    n_off = dr.minimum(dr.maximum(dr.floor(-rise / c_off), 0.0), MAX_CROSSINGS)
    return Int(n_on) - Int(n_off)


def reference_level(dr, Float, anchor, k_on, k_off, c_on, c_off):
    """Reference level from the pixel's initial level and its integer ON/OFF event counts.

    Kept exact by construction instead of accumulated (``ref += C`` drifts by a rounding error per event):
    with equal thresholds it depends on ``k_on - k_off`` only, so a pixel whose counts return to the same net
    value is back in bit-identical state, which is what makes periodic scans provably periodic in events.
    """
    symmetric = Float(k_on - k_off) * c_on
    general = Float(k_on) * c_on - Float(k_off) * c_off
    return anchor + dr.select(c_on == c_off, symmetric, general)


def expand_crossings(pixel, n, log_prev, log_now, log_ref, c_on, c_off, t0: float, t1: float):
    """Events of the pixels that fired during (t0, t1].

    All inputs are 1-D arrays over the *firing* pixels (``n != 0``). Crossing k (1-based) of a pixel sits at
    level ``ref + k*C*sign``; its time is where the linear segment from ``log_prev`` (at t0) to ``log_now`` (at
    t1) meets that level. Returns (pixel index, time in seconds float64, polarity int8), unsorted.
    """
    n = np.asarray(n, dtype=np.int64)
    counts = np.abs(n)
    if len(n) == 0:
        return np.empty(0, np.int64), np.empty(0, np.float64), np.empty(0, np.int8)
    check_event_count(float(counts.sum()), t0, t1, len(n), "host")     # (the firing pixels' count)
    pixel = np.asarray(pixel, dtype=np.int64)
    lp, ln, ref = (np.asarray(a, dtype=np.float64) for a in (log_prev, log_now, log_ref))
    step = np.where(n > 0, np.asarray(c_on, dtype=np.float64), np.asarray(c_off, dtype=np.float64))
    sign = np.sign(n)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv_rise = 1.0 / (ln - lp)        # once a pixel, multiplied per crossing: event_select.crossing_time
    if counts.max() > 1:  # repeat each firing pixel once per crossing; k = 1..n within the pixel
        idx = np.repeat(np.arange(len(n)), counts)
        k = np.arange(len(idx), dtype=np.int64) - (np.cumsum(counts) - counts)[idx] + 1
        pixel, lp, inv_rise, ref, step, sign = pixel[idx], lp[idx], inv_rise[idx], ref[idx], step[idx], sign[idx]
    else:                 # the common case with short steps: one crossing per pixel
        k = 1
    with np.errstate(invalid="ignore"):
        frac = (ref + sign * k * step - lp) * inv_rise
    frac = np.clip(np.nan_to_num(frac, nan=1.0), 0.0, 1.0)
    return pixel, t0 + frac * (t1 - t0), sign.astype(np.int8)


def time_order(t_us: np.ndarray, step_start_us: int) -> np.ndarray:
    """Stable time order of one step's events on the host. Offsets within a step usually fit 16 bits, where
    NumPy's stable sort is a radix sort (about 8x faster than comparison sorting here)."""
    offset = t_us - step_start_us
    if len(offset) and offset.min() >= 0 and offset.max() < 2**16:
        return np.argsort(offset.astype(np.uint16), kind="stable")
    return np.argsort(t_us, kind="stable")



# ======================================================================================== pixel realism
# Every effect below is off in the ``ideal`` preset. Dense per-pixel state evolves in Dr.Jit (low-pass,
# leak, noise draws); the sparse steps act on the few events of a step in NumPy (refractory, readout cap).

import functools  # noqa: E402
from dataclasses import asdict, dataclass, fields  # noqa: E402


# Upper limits of the pixel's times and rates: far beyond any sensor's, so that only a unit slip meets them (a
# refractory of 500 "s" was taken; a shot-noise rate of 1e6 Hz asked the default steps for 100,000 steps in 10 ms,
# shot noise needing rate x duration / SHOT_NOISE_PER_STEP of them, and ran for minutes without a word).
PIXEL_UPPER_LIMITS = {
    "refractory_s": (1.0, "seconds; sensors' refractory periods are 1 us to 10 ms"),
    "leak_rate_hz": (1e4, "events per pixel per second; sensors leak 0.01-1 Hz"),
    "shot_noise_hz": (1e3, "events per pixel per second; sensors' dark noise is 0.01-10 Hz, v2e's noisy 5 Hz"),
    "cutoff_hz": (1e5, "hertz; photoreceptors' bright cutoffs are 100 Hz to a few kHz"),
    "timestamp_resolution_us": (1e6, "microseconds; sensors' clocks tick every 1 us"),
}


@dataclass
class PixelConfig:
    """Parameters of the event pixel (log units for thresholds, seconds, hertz, radiance for intensities)."""
    threshold_on: float = 0.2
    threshold_off: float = 0.2
    threshold_sigma: float = 0.0          # per-pixel ON/OFF threshold mismatch (fixed per pixel), log units
    threshold_jitter: float = 0.0         # the reset's threshold noise: drawn at each event, held to the next
    refractory_s: float = 0.0             # no two events of a pixel closer than this
    leak_rate_hz: float = 0.0             # spontaneous ON events per pixel per second (reference drift)
    leak_jitter: float = 0.0              # relative per-pixel spread of the leak rate
    shot_noise_hz: float = 0.0            # noise events per pixel per second in the dark
    shot_noise_bright_factor: float = 0.25  # rate at intensity >= bright_intensity, relative to the dark rate
    cutoff_hz: float = 0.0                # photoreceptor 3 dB cutoff at bright_intensity (0: no low-pass)
    cutoff_min_fraction: float = 0.01     # dim pixels: cutoff never below this fraction of cutoff_hz
    bright_intensity: float = 1.0         # radiance treated as "bright" by the low-pass and shot noise
    linlog_threshold: float = DEFAULT_LINLOG_THRESHOLD   # radiance below which the response is linear
    timestamp_resolution_us: float = 0.0  # > 0: timestamps floored to this clock (sensors: 1 us)
    readout_cap: float = 0.0              # events per second the readout can pass (0: unlimited)
    readout_cap_native_pixels: int = 0    # > 0: readout_cap is for a sensor of this many pixels; scaled by film
    seed: int = 0                         # seeds the mismatch and every noise draw (an integer >= 0)
    preset: str = "ideal"

    @property
    def stochastic(self) -> bool:
        """True if the state can drift or draw noise (then periodic event copying is invalid)."""
        return bool(self.threshold_jitter or self.leak_rate_hz or self.shot_noise_hz or self.cutoff_hz
                    or self.readout_cap or self.refractory_s)

    def validate(self, where: str = "pixel model") -> "PixelConfig":
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name in ("preset",):
                continue
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ConfigError(f"{where}: {f.name} = {v!r}: must be a finite number")
        for name in ("threshold_on", "threshold_off", "linlog_threshold", "bright_intensity"):
            if getattr(self, name) <= 0:
                raise ConfigError(f"{where}: {name} = {getattr(self, name)!r}: must be > 0")
        for name in ("threshold_on", "threshold_off"):       # the command line's bound, for the library too
            if getattr(self, name) > MAX_THRESHOLD:
                raise ConfigError(f"{where}: {name} = {getattr(self, name)!r}: allowed range is (0, {MAX_THRESHOLD:g}] "
                                  "(log units)")
        for name in ("threshold_sigma", "threshold_jitter", "refractory_s", "leak_rate_hz", "leak_jitter",
                     "shot_noise_hz", "cutoff_hz", "timestamp_resolution_us", "readout_cap",
                     "readout_cap_native_pixels"):
            if getattr(self, name) < 0:
                raise ConfigError(f"{where}: {name} = {getattr(self, name)!r}: must be >= 0 (rates, times and "
                                 "spreads cannot be negative)")
        for name, (hi, why) in PIXEL_UPPER_LIMITS.items():
            if getattr(self, name) > hi:
                raise ConfigError(f"{where}: {name} = {getattr(self, name)!r}: allowed range is [0, {hi:g}] ({why})")
        # thresholds are floored at C / 10 whatever the spread; beyond C / 2 that floor would hold more than 4 % of
        # them and the spread would no longer be the one asked for (v2e's "noisy" sensor, sigma 0.05 at C = 0.2, is
        # C / 4, which the bound of C / 4 exclusive refused)
        c = min(self.threshold_on, self.threshold_off)
        for name in ("threshold_sigma", "threshold_jitter"):
            if getattr(self, name) * 2 > c:
                raise ConfigError(f"{where}: {name} = {getattr(self, name)}: with thresholds of {c} more than 4 % of "
                                 f"the thresholds would sit on their floor of C / 10; must be <= {c / 2:g}")
        if self.seed != int(self.seed) or self.seed < 0:        # NumPy's generators take no negative seed
            raise ConfigError(f"{where}: seed = {self.seed!r}: must be an integer >= 0")
        for name in ("shot_noise_bright_factor", "cutoff_min_fraction"):
            if not 0 < getattr(self, name) <= 1:
                raise ConfigError(f"{where}: {name} = {getattr(self, name)!r}: must be in (0, 1]")
        if self.readout_cap and self.readout_cap < READOUT_BINS_PER_MS * 1000 * 2:
            raise ConfigError(f"{where}: readout_cap = {self.readout_cap:g} events/s is below the smallest the "
                             f"limiter can enforce ({READOUT_BINS_PER_MS * 2000:g})")
        return self

    def as_dict(self) -> dict:
        return asdict(self)

    def readout_cap_for(self, n_pix: int) -> float:
        """The readout cap (events/s) of a film of ``n_pix`` pixels (:func:`film_readout_cap`)."""
        return film_readout_cap(self.readout_cap, self.readout_cap_native_pixels, n_pix)

    def check_film(self, n_pix: int, where: str = "pixel model") -> None:
        """Refuse a readout cap that, scaled to a film of ``n_pix`` pixels, falls below what the limiter can
        enforce: its budget per bin rounded down to nothing, and every event was dropped (the davis346 cap on
        an 8x8 film dropped all 46,080 of them, with a note)."""
        cap = self.readout_cap_for(n_pix)
        if self.readout_cap and cap < READOUT_BINS_PER_MS * 2000:
            raise ConfigError(f"{where}: readout_cap = {self.readout_cap:g} events/s for "
                              f"{self.readout_cap_native_pixels} pixels is {cap:g} events/s on this film of {n_pix} "
                              f"pixels, below the smallest the limiter can enforce ({READOUT_BINS_PER_MS * 2000:g}): "
                              "render a larger film, or set readout_cap_native_pixels = 0 to keep the cap unscaled")


# Presets. Sources (docs/pixel_model.md): v2e (Hu et al., CVPRW 2021) defaults for a DVS: thresholds
# 0.2, mismatch 0.03, leak 0.1 Hz with 10% spread; its "noisy" setting: 5 Hz shot noise, 30 Hz cutoff.
# Lichtsteiner et al. (JSSC 2008): 2.1% threshold mismatch. iniVation DAVIS346: 12 MEvt/s readout.
# Finateu et al. (ISSCC 2020, the Sony/Prophesee IMX636): 1280x720, 1.066 GEPS readout. IEBCS (Joubert et
# al. 2021): ~100 us refractory for a Prophesee sensor. docs/design.md, "Physics", sums them up.
PRESETS = {
    "ideal": {},
    "davis346": dict(threshold_sigma=0.03, refractory_s=5e-4, leak_rate_hz=0.1, leak_jitter=0.1,
                     shot_noise_hz=1.0, cutoff_hz=300.0, timestamp_resolution_us=1.0, readout_cap=12e6,
                     readout_cap_native_pixels=346 * 260),
    "prophesee_gen4": dict(threshold_on=0.25, threshold_off=0.25, threshold_sigma=0.03, refractory_s=1e-4,
                           leak_rate_hz=0.1, leak_jitter=0.1, shot_noise_hz=0.1, cutoff_hz=1000.0,
                           timestamp_resolution_us=1.0, readout_cap=1.066e9,
                           readout_cap_native_pixels=1280 * 720),
}


def pixel_config(preset: str = "ideal", where: str = "pixel model", **overrides) -> PixelConfig:
    if preset not in PRESETS:
        raise ConfigError(f"{where}: unknown preset {preset!r}; allowed: {', '.join(PRESETS)}")
    names = {f.name for f in fields(PixelConfig)}
    unknown = set(overrides) - names
    if unknown:
        raise ConfigError(f"{where}: unknown pixel parameter {sorted(unknown)[0]!r}; allowed: {', '.join(sorted(names))}")
    values = dict(PRESETS[preset], **{k: v for k, v in overrides.items() if v is not None})
    return PixelConfig(preset=preset, **values).validate(where)


def preset_and_overrides(preset: str | None, pixel: dict | None, where: str = "pixel model") -> tuple:
    """(preset, the other parameters) of a ``pixel`` dict that may name its preset itself, as
    ``PixelConfig.as_dict()`` and a render's metadata do (or of a preset's name alone): its name is taken where
    ``preset`` is None or the same; two different names are refused (one line). ``preset`` None stays None
    (the caller's default)."""
    if isinstance(pixel, str):        # pixel="davis346": the preset by its name
        pixel = {"preset": pixel}
    elif pixel is not None and not isinstance(pixel, dict):
        raise ConfigError(f"{where}: pixel = {pixel!r}: expected a preset's name or a dict of parameters "
                          f"(allowed presets: {', '.join(PRESETS)})")
    values = dict(pixel or {})
    named = values.pop("preset", None)
    if named is not None and preset is not None and named != preset:
        raise ConfigError(f"{where}: pixel['preset'] = {named!r} and preset = {preset!r}: name one preset "
                          f"(allowed: {', '.join(PRESETS)})")
    return (preset if preset is not None else named), values


def explicit_thresholds(threshold, threshold_on, threshold_off) -> dict:
    """The ON and OFF thresholds a caller names: each its own where given, else the common ``threshold``
    (None where neither is given). One rule for ``render_events`` and ``events_from_frames``, and so for both
    commands' --threshold / --threshold-on / --threshold-off."""
    return {"threshold_on": threshold if threshold_on is None else threshold_on,
            "threshold_off": threshold if threshold_off is None else threshold_off}


def given_once(arguments: dict, pixel: dict, where: str = "pixel model") -> None:
    """Refuse a parameter given both as its own argument (``arguments``: name -> value or None, e.g. a
    render's ``threshold``) and in the ``pixel`` dict with another value: one would win silently while the
    other is what the caller recorded (a sweep's ``render.threshold`` column beside ``pixel.threshold_on``)."""
    for name, v in arguments.items():
        if v is not None and pixel.get(name) is not None and pixel[name] != v:
            raise ConfigError(f"{where}: {name} given twice, {v!r} as an argument and {pixel[name]!r} in the pixel "
                              "parameters: give it once")


def sample_thresholds(rng: np.random.Generator, n: int, nominal: float, sigma: float) -> np.ndarray:
    """Per-pixel thresholds ~ N(nominal, sigma), floored at nominal / 10 so none is ever <= 0."""
    if sigma == 0:
        return np.full(n, nominal, np.float32)
    return np.maximum(rng.normal(nominal, sigma, n), nominal / 10).astype(np.float32)


def sensor_constants(config: PixelConfig, n_pix: int) -> dict:
    """The per-pixel constants of a sensor of ``n_pix`` pixels with this model, drawn from its seed: ON and OFF
    thresholds (mismatch), and with a leak each pixel's leak rate and its phase in the leak cycle (a sensor in
    steady state), as read-only float32 arrays ("c_on", "c_off"; "leak_rate", "leak_phase" or None).

    The same seed and model are the same sensor, so the draws are kept for the last few sensors
    (:func:`_sensor_draws`): drawing them took 4-5 ms at 346x260 and 45 ms at 1280x720 on every render (NumPy's
    normal), the largest single item of the realistic pixel's host time in an H200's 100-step demo profile
    (docs/design.md), and sweeps and dataset renders make many renders of one sensor. The values are those of
    one draw in this order whatever the cache holds."""
    return _sensor_draws(int(config.seed), int(n_pix), float(config.threshold_on), float(config.threshold_off),
                         float(config.threshold_sigma), float(config.leak_rate_hz), float(config.leak_jitter))


@functools.lru_cache(maxsize=4)
def _sensor_draws(seed, n_pix, threshold_on, threshold_off, sigma, leak_rate_hz, leak_jitter) -> dict:
    rng = np.random.default_rng(seed)
    out = {"c_on": sample_thresholds(rng, n_pix, threshold_on, sigma),
           "c_off": sample_thresholds(rng, n_pix, threshold_off, sigma), "leak_rate": None, "leak_phase": None}
    if leak_rate_hz:
        out["leak_rate"] = (leak_rate_hz * np.maximum(1 + leak_jitter * rng.standard_normal(n_pix), 0)
                            ).astype(np.float32)
        out["leak_phase"] = rng.random(n_pix).astype(np.float32)
    for value in out.values():
        if value is not None:
            value.flags.writeable = False          # shared by every render of this sensor
    return out


def lowpass_cutoff(xp, intensity, cutoff_hz, bright_intensity, min_fraction):
    """The photoreceptor's cutoff at ``intensity`` (``xp``: drjit or numpy): proportional to it up to
    ``bright_intensity``, never below ``min_fraction`` of ``cutoff_hz``."""
    return cutoff_hz * xp.clip(intensity / bright_intensity, min_fraction, 1.0)


def lowpass_alpha(dr, intensity, dt, cutoff_hz, bright_intensity, min_fraction):
    """Blend factor of the photoreceptor's first-order low-pass over dt (``lowpass_cutoff``)."""
    f = lowpass_cutoff(dr, intensity, cutoff_hz, bright_intensity, min_fraction)
    return 1.0 - dr.exp(-2.0 * math.pi * f * dt)


def shot_noise_hazard(dr, intensity, dt, rate_hz, bright_intensity, bright_factor):
    """The expected number of noise events in dt (rate x dt): the rate falls linearly from rate_hz (dark) to
    bright_factor * rate_hz at ``bright_intensity``."""
    frac = dr.clip(intensity / bright_intensity, 0.0, 1.0)
    rate = rate_hz * (1.0 - (1.0 - bright_factor) * frac)
    return rate * dt


def refractory_crossings(pixel, t, last_emit, period):
    """Refractory selection for one step's crossings, as ``expand_crossings`` returns them: grouped by pixel,
    time-ordered and evenly spaced within a pixel (linear brightness between rendered instants). Closed form,
    identical to greedy selection: the first crossing at least ``period`` after the pixel's last kept event,
    then every ceil(period / spacing)-th one. Updates ``last_emit`` (per-pixel, seconds) in place.
    Returns (keep mask, per-group (pixel, first kept time) for :func:`refractory_extra`)."""
    n = len(t)
    if n == 0:
        return np.zeros(0, bool), (np.empty(0, np.int64), np.empty(0))
    start = np.r_[0, np.nonzero(np.diff(pixel))[0] + 1]
    size = np.diff(np.r_[start, n])
    gp, t0g = pixel[start], t[start]
    multi = size > 1
    spacing = np.where(multi, t[np.minimum(start + 1, n - 1)] - t0g, 1.0)
    wait = last_emit[gp] + period - t0g                     # > 0: the first crossing is too early
    with np.errstate(invalid="ignore", divide="ignore"):
        first_multi = np.maximum(0, np.ceil(wait / spacing - 1e-9))
    first = np.where(multi, np.nan_to_num(first_multi, nan=0.0, neginf=0.0), np.where(wait <= 0, 0, 1))
    with np.errstate(divide="ignore"):      # crossings at one instant (spacing 0): infinite stride, one kept
        stride = np.where(multi, np.maximum(1, np.ceil(period / spacing - 1e-9)), 1)
    rank = np.arange(n) - np.repeat(start, size)
    f_r, s_r = np.repeat(first, size), np.repeat(stride, size)
    keep = (rank >= f_r) & (((rank - f_r) % s_r) == 0)
    kept_groups = first < size
    finite = np.isfinite(stride)
    last_idx = start + first + np.where(finite, stride * np.floor((size - 1 - first) / np.where(finite, stride, 1)),
                                        0)
    last_emit[gp[kept_groups]] = t[last_idx[kept_groups].astype(np.int64)]
    first_kept = np.where(kept_groups, t[np.minimum(start + first, n - 1).astype(np.int64)], np.inf)
    return keep, (gp, first_kept)


def refractory_extra(pixel, t, before, crossings, last_emit, period):
    """Refractory check of extra single events (shot noise; at most one per pixel and step) against the step's
    kept crossings: kept only if at least ``period`` after the pixel's previous emission (``before``: its
    last_emit before this step) and outside [first kept - period, last kept + period] of this step's crossings
    (conservative: the gap guarantee always holds). Touches only these pixels."""
    gp, first_kept = crossings                           # gp ascending (compress order)
    i = np.minimum(np.searchsorted(gp, pixel), max(len(gp) - 1, 0))
    has = (len(gp) > 0) & (gp[i] == pixel) if len(gp) else np.zeros(len(pixel), bool)
    first = np.where(has, first_kept[i] if len(gp) else np.inf, np.inf)
    after_all = t >= last_emit[pixel] + period
    keep = (t >= before + period) & (~np.isfinite(first) | (t <= first - period) | after_all)
    last_emit[pixel[keep]] = np.maximum(last_emit[pixel[keep]], t[keep])
    return keep
