"""Optional: drive the galvo from an NI-DAQmx analog-output card instead of a function generator
(``pip install nidaqmx``). The card plays one period of the scan curve's sampled voltages, regenerated
continuously; the curve is checked against the same envelope as for generators, before the card is touched.
Untested on hardware here (neither the package nor a card is available): the tests check the calls it makes
against a stand-in module.
"""
from __future__ import annotations

import numpy as np

from .controller import GalvoController
from .spec import GalvoSpec, SafetyError, finite_number

MAX_RATE = 10e6                # samples per second and channel: beyond any analog-output card
MAX_SAMPLES = 10_000_000       # per channel, one period: a 1e-4 Hz circle asked for 7.45 GiB


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
        GalvoController(None, "keysight", self.spec).plan(curve)
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
        if n < 16:
            raise SafetyError(f"{self.rate:g} samples/s give only {n} samples per {period * 1e3:g} ms period (need 16)")
        t = np.arange(n) / self.rate
        ax, ay = curve.angles(t)
        volts = np.degrees(np.stack([ax, ay])) * self.spec.volts_per_deg
        if np.abs(volts).max() > self.spec.max_volts:
            raise SafetyError(f"the waveform reaches {np.abs(volts).max():.3g} V, beyond +-{self.spec.max_volts:g} V")
        return volts

    def start(self, curve) -> None:
        if self.task is not None:      # a second task on the same card would leave the first one running
            raise SafetyError("the card is already playing a scan: stop() it first")
        volts = self.waveform(curve)
        try:
            import nidaqmx
            from nidaqmx.constants import AcquisitionType
        except ImportError:
            raise SafetyError("NI-DAQmx output needs the nidaqmx package (pip install nidaqmx) and NI's driver") from None
        task = nidaqmx.Task()
        try:
            for ch in self.channels:
                task.ao_channels.add_ao_voltage_chan(f"{self.device}/{ch}", min_val=-self.spec.max_volts,
                                                     max_val=self.spec.max_volts)
            task.timing.cfg_samp_clk_timing(self.rate, sample_mode=AcquisitionType.CONTINUOUS,
                                            samps_per_chan=volts.shape[1])
            task.write(volts, auto_start=False)
            task.start()
        except BaseException:
            task.close()
            raise
        self.task = task

    def stop(self) -> None:
        """Stop, drive both outputs to 0 V, release the card."""
        if self.task is None:
            return
        try:
            self.task.stop()
            self.task.close()
        finally:
            self.task = None
            try:
                import nidaqmx
                with nidaqmx.Task() as zero:
                    for ch in self.channels:
                        zero.ao_channels.add_ao_voltage_chan(f"{self.device}/{ch}")
                    zero.write([0.0, 0.0], auto_start=True)
            except Exception:  # noqa: BLE001  (best effort when the card is gone)
                pass
