"""Optional: drive the galvo from an NI-DAQmx analog-output card instead of a function generator
(``pip install nidaqmx``). The card plays one period of the scan curve's sampled voltages, regenerated
continuously, faded in from rest before and out to rest after (``DAQmxOutput.ramp``); the curve is checked
against the same envelope as for generators, before the card is touched.
Untested on hardware here (neither the package nor a card is available): the tests check the calls it makes
against a stand-in module.
"""
from __future__ import annotations

import contextlib

import numpy as np

from .controller import check_envelope
from .spec import GalvoSpec, SafetyError, finite_number

MAX_RATE = 10e6                # samples per second and channel: beyond any analog-output card
MAX_SAMPLES = 10_000_000       # per channel, one period: a 1e-4 Hz circle asked for 7.45 GiB
MIN_SAMPLES = 100              # per period: 16 (the first limit) played a 1 kHz circle as a 16-step staircase
RAMP_TIME_S = 0.5              # the amplitude (and offset) ramped in and out over this, as the generators do


class DAQmxOutput:
    def __init__(self, device: str = "Dev1", channels=("ao0", "ao1"), spec: GalvoSpec | None = None,
                 rate: float = 100_000.0):
        if (isinstance(channels, (str, bytes)) or not hasattr(channels, "__len__") or len(channels) != 2
                or not all(isinstance(c, str) and c for c in channels)):
            # a string "ao0" was taken as the three channels a, o, 0
            raise SafetyError(f"channels = {channels!r}: expected two channel names (x, y), e.g. ('ao0', 'ao1')")
        rate = finite_number(rate, "rate")
        if not 0 < rate <= MAX_RATE:
            raise SafetyError(f"rate = {rate:g}: allowed range is (0, {MAX_RATE:g}] samples per second")
        self.device, self.channels, self.spec, self.rate = device, tuple(channels), spec or GalvoSpec(), rate
        self.task = None

    def waveform(self, curve) -> np.ndarray:
        """(2, N) volts for one scan period, after the envelope check (raises SafetyError, touches nothing)."""
        # the envelope only: a generator's smallest sine (1 mVpp at the first of its ramp steps) is no card's
        check_envelope(self.spec, curve)
        period = curve.period
        if period * self.rate > MAX_SAMPLES:
            raise SafetyError(f"one {period:g} s scan period at {self.rate:g} samples/s needs "
                              f"{period * self.rate:.3g} samples a channel: at most {MAX_SAMPLES:,} (a faster scan "
                              "or a lower rate)")
        n = int(round(period * self.rate))
        if abs(period * self.rate - n) > 1e-6 * max(n, 1):
            # the card regenerates the buffer: a partial period would make the mirror jump at every wrap
            raise SafetyError(f"{self.rate:g} samples/s give {period * self.rate:.4g} samples per "
                              f"{period * 1e3:g} ms period: must be a whole number (e.g. {n / period:.6g} samples/s)")
        if n < MIN_SAMPLES:
            raise SafetyError(f"{self.rate:g} samples/s give only {n} samples per {period * 1e3:g} ms period (need "
                              f"{MIN_SAMPLES}: a coarser one is a staircase the mirror follows)")
        t = np.arange(n) / self.rate
        ax, ay = curve.angles(t)
        volts = np.degrees(np.stack([ax, ay])) * self.spec.volts_per_deg
        if np.abs(volts).max() > self.spec.max_volts:
            raise SafetyError(f"the waveform reaches {np.abs(volts).max():.3g} V, beyond +-{self.spec.max_volts:g} V")
        return volts

    def ramp(self, volts: np.ndarray, first: int = 0, down: bool = False) -> np.ndarray:
        """(2, M) volts: whole periods of ``volts`` from its sample ``first`` on, times an envelope rising from
        0 (or falling to 0, ``down``) over ``RAMP_TIME_S``: the scan faded in from rest, or out to rest from
        where the card stopped. Until 2026-11-27 the card started on the curve's first sample (9.6 V from rest
        for a 12 deg circle) and stopped by holding its last one, then jumped to 0 V."""
        n = volts.shape[1]
        periods = max(1, int(np.ceil(RAMP_TIME_S * self.rate / n)))
        played = np.roll(volts, -first, axis=1)
        envelope = np.linspace(0.0, 1.0, periods * n + 1)[1:]           # reaches 1 at the last sample
        return np.tile(played, periods) * (envelope[::-1] - envelope[0] if down else envelope)

    def _play(self, nidaqmx, volts, continuous: bool):
        """A task playing ``volts``: regenerated for ever (``continuous``) or once, then released."""
        from nidaqmx.constants import AcquisitionType
        task = nidaqmx.Task()
        try:
            for ch in self.channels:
                task.ao_channels.add_ao_voltage_chan(f"{self.device}/{ch}", min_val=-self.spec.max_volts,
                                                     max_val=self.spec.max_volts)
            task.timing.cfg_samp_clk_timing(self.rate, samps_per_chan=volts.shape[1], sample_mode=(
                AcquisitionType.CONTINUOUS if continuous else AcquisitionType.FINITE))
            task.write(volts, auto_start=False)
            task.start()
            if not continuous:
                task.wait_until_done(timeout=10.0 + volts.shape[1] / self.rate)
        except BaseException:
            task.close()
            raise
        if not continuous:
            task.close()
        return task

    def start(self, curve) -> None:
        if self.task is not None:      # a second task on the same card would leave the first one running
            raise SafetyError("the card is already playing a scan: stop() it first")
        volts = self.waveform(curve)
        try:
            import nidaqmx
            import nidaqmx.constants  # noqa: F401
        except ImportError:
            raise SafetyError("NI-DAQmx output needs the nidaqmx package (pip install nidaqmx) and NI's driver") from None
        faded_in = False
        try:
            self._play(nidaqmx, self.ramp(volts), continuous=False)     # faded in; the card holds its last sample
            faded_in = True
            self.task, self.volts = self._play(nidaqmx, volts, continuous=True), volts
        except BaseException:
            # the card holds the fade-in's last sample (up to full deflection) or wherever it was cut: back to
            # rest before the error leaves (a failed start left a 12 deg circle held at 9.6 V, a review found)
            self._rest(nidaqmx, volts if faded_in else None, 0)
            raise

    def stop(self) -> None:
        """Stop, fade out to 0 V from where the card stopped (``ramp``), release the card; where the fade
        fails (the card gone), drive both outputs to 0 V at once."""
        if self.task is None:
            return
        import nidaqmx
        volts, first = None, 0
        try:
            self.task.stop()
            volts, first = self.volts, int(self.task.out_stream.total_samp_per_chan_generated) % self.volts.shape[1]
        finally:
            with contextlib.suppress(Exception):
                self.task.close()
            self.task = None
            self._rest(nidaqmx, volts, first)

    def _rest(self, nidaqmx, volts, first: int) -> None:
        """Both outputs back to 0 V: faded out from ``volts``'s sample ``first`` (the one after the sample the
        card holds), or at once where there is nothing to fade from or the fade fails. Ctrl-C and SIGTERM wait
        for it (``signals.signals_held``)."""
        from .signals import signals_held
        with signals_held():
            if volts is not None:
                try:
                    self._play(nidaqmx, self.ramp(volts, first, down=True), continuous=False)
                    return
                except Exception:  # noqa: BLE001  (the card gone: the direct way below)
                    pass
            with contextlib.suppress(Exception):     # best effort when the card is gone
                with nidaqmx.Task() as zero:
                    for ch in self.channels:
                        zero.ao_channels.add_ao_voltage_chan(f"{self.device}/{ch}")
                    zero.write([0.0, 0.0], auto_start=True)
