"""NI-DAQ digitiser (nidaqmx): finite, hardware-triggered two-channel acquisition.

``nidaqmx`` imports without NI's driver and fails on first use; :class:`NidaqDigitiser`
checks the driver when constructed and raises :class:`DriverNotInstalledError` with one line.

One task per :meth:`configure`, committed at once (the device is reserved and programmed, so a
bad channel, rate or terminal configuration is refused there, and :meth:`arm` is quick). Each
acquisition starts it (:meth:`arm`) and stops it back to the committed state (:meth:`read`),
also after a trigger timeout, so the next attempt acquires. With pretrigger samples the task
uses a reference trigger, and the device ignores a trigger that comes before it holds the
pretrigger samples: :meth:`arm` returns only once it does. Only :meth:`safe_state` clears the
task. DAQmx errors are reported as one line naming the device, the channel and what to check.
"""

from __future__ import annotations

import logging
import math
from typing import Any

import numpy as np

from instruments.clock import Clock, SystemClock
from instruments.errors import (
    DriverNotInstalledError,
    InstrumentError,
    InstrumentTimeout,
    LimitError,
)
from instruments.interfaces import Acquisition, AcquisitionConfig

__all__ = ["TERMINAL_CONFIGS", "NidaqDigitiser", "daq_error_text"]

log = logging.getLogger(__name__)

#: bench-file names of the analog-input terminal configurations -> nidaqmx's
#: ``TerminalConfiguration`` members ("default": the device's own default for the channel)
TERMINAL_CONFIGS: dict[str, str] = {
    "default": "DEFAULT",
    "RSE": "RSE",
    "NRSE": "NRSE",
    "differential": "DIFF",
    "pseudodifferential": "PSEUDO_DIFF",
}

#: DAQmx error codes this driver explains (numbers from NI-DAQmx's error list)
SAMPLES_NOT_YET_AVAILABLE = -200284
INVALID_TASK = -200088

#: what to check, per DAQmx error code
_HINTS: dict[int, str] = {
    SAMPLES_NOT_YET_AVAILABLE: "no trigger reached {trigger}: check the generator's trigger "
    "output is cabled to {trigger} and that the generator fired",
    -200278: "the record was already read (arm again before reading)",
    -200279: "samples were overwritten before they were read: lower the sample rate",
    -200010: "the device's buffer overflowed: lower the sample rate",
    INVALID_TASK: "the acquisition task was cleared (by the safe state or another program): "
    "configure again",
    -200220: "no device {device}: check daq.device in the bench file against the name NI MAX shows",
    -200170: "a channel of {channels} does not exist on {device}: check daq.velocity_channel "
    "and daq.reference_channel in the bench file",
    -200332: "the sample rate is above what {device} can do on {n} channels: lower the rate",
    -200077: "{device} refused a setting (terminal configuration {terminal}, input range, rate "
    "or pretrigger): check the daq section of the bench file against the device",
    -200479: "the task was running when it was changed",
    -201003: "{device} cannot be accessed: check it is powered and connected, then reset it in "
    "NI MAX",
    -50103: "{device} is in use by another task or program: close NI MAX test panels and other "
    "acquisition programs",
}


def _error_code(exc: BaseException) -> int | None:
    code = getattr(exc, "error_code", None)
    return int(code) if isinstance(code, int) else None


def daq_error_text(exc: BaseException, **where: Any) -> str:
    """One line for a DAQmx error: what to check (filled from ``where``: device, channels,
    trigger, n, terminal), NI's own first line and the error code."""
    code = _error_code(exc)
    first = next((ln.strip() for ln in str(exc).splitlines() if ln.strip()), type(exc).__name__)
    ni = f"NI: {first}" + (f"; DAQmx error {code}" if code is not None else "")
    hint = _HINTS.get(code) if code is not None else None
    if hint is None:
        return ni
    fields = {"device": "?", "channels": "?", "trigger": "?", "n": "?", "terminal": "?"}
    fields.update({k: v for k, v in where.items() if v is not None})
    return f"{hint.format(**fields)} ({ni})"


def _load_nidaqmx() -> Any:
    try:
        import nidaqmx
        import nidaqmx.system
    except ImportError as exc:
        raise DriverNotInstalledError(f"nidaqmx Python package not installed ({exc})") from None
    try:
        nidaqmx.system.System.local().driver_version  # noqa: B018 - first use loads the driver
    except Exception as exc:
        raise DriverNotInstalledError(
            f"NI-DAQmx driver not installed or not loadable on this machine ({type(exc).__name__})"
        ) from None
    return nidaqmx


class NidaqDigitiser:
    """Implements ``Digitiser`` on an NI device.

    Parameters
    ----------
    device:
        NI device name (``"Dev1"``).
    max_rate_Hz:
        The bench's ceiling on the rate per channel (S/s; the bench file's ``daq.max_rate``), on
        top of the device's own: ``min(ai_max_single_chan_rate, ai_max_multi_chan_rate /
        channels)`` (NI documents ``ai_max_multi_chan_rate`` as the device's aggregate rate).
    terminal_config:
        Input terminal configuration of both channels, a key of :data:`TERMINAL_CONFIGS`
        (``"RSE"``, ``"NRSE"``, ``"differential"``, ``"pseudodifferential"`` or ``"default"``).
    clock:
        Time source for the pretrigger wait (default: the system clock).
    """

    N_CHANNELS = 2

    def __init__(
        self,
        device: str = "Dev1",
        *,
        max_rate_Hz: float | None = None,
        terminal_config: str = "default",
        clock: Clock | None = None,
    ) -> None:
        if terminal_config not in TERMINAL_CONFIGS:
            raise LimitError(
                f"NI-DAQ {device}: terminal configuration {terminal_config!r} is not one of "
                f"{', '.join(TERMINAL_CONFIGS)}"
            )
        self._nidaqmx = _load_nidaqmx()
        self.device = device
        self.terminal_config = terminal_config
        self._max_rate_Hz = max_rate_Hz
        self._clock: Clock = clock if clock is not None else SystemClock()
        self._task: Any = None
        self._running = False
        self._config: AcquisitionConfig | None = None
        self._rate_Hz: float | None = None
        self._product = ""
        try:
            self._dev = self._nidaqmx.system.Device(device)
            self._product = str(self._dev.product_type)
        except Exception as exc:
            raise InstrumentError(f"NI-DAQ {device}: {self._explain(exc)}") from None

    # --- limits ----------------------------------------------------------------------------------
    def device_max_rate_per_channel_Hz(self, n_channels: int = N_CHANNELS) -> float:
        """The device's highest rate per channel (S/s) for ``n_channels``: its single-channel
        maximum, and its aggregate maximum (``ai_max_multi_chan_rate``) shared by the channels."""
        limits = []
        for name, per in (("ai_max_single_chan_rate", 1), ("ai_max_multi_chan_rate", n_channels)):
            try:
                limits.append(float(getattr(self._dev, name)) / per)
            except Exception as exc:
                log.warning("NI-DAQ %s: %s unreadable: %s", self.device, name, exc)
        return min(limits) if limits else math.inf

    def max_rate_per_channel_Hz(self, n_channels: int = N_CHANNELS) -> float:
        """The highest rate per channel (S/s) allowed: the device's and the bench's ceiling."""
        device = self.device_max_rate_per_channel_Hz(n_channels)
        return device if self._max_rate_Hz is None else min(device, float(self._max_rate_Hz))

    def _where(self, config: AcquisitionConfig | None = None) -> dict[str, Any]:
        cfg = config or self._config
        return {
            "device": f"{self.device} ({self._product})" if self._product else self.device,
            "channels": None if cfg is None else f"{cfg.velocity_channel}, {cfg.reference_channel}",
            "trigger": None if cfg is None else cfg.trigger_source,
            "n": self.N_CHANNELS,
            "terminal": self.terminal_config,
        }

    def _explain(self, exc: BaseException, config: AcquisitionConfig | None = None) -> str:
        return daq_error_text(exc, **self._where(config))

    # --- acquisition -----------------------------------------------------------------------------
    def configure(self, config: AcquisitionConfig) -> float:
        """Create and commit the finite task; returns the coerced per-channel rate (S/s) read
        back from the device."""
        limit = self.max_rate_per_channel_Hz(self.N_CHANNELS)
        if config.sample_rate_Hz > limit * (1 + 1e-12):
            raise LimitError(
                f"NI-DAQ {self.device}: {config.sample_rate_Hz:g} S/s per channel is above "
                f"{limit:g} S/s, the most for {self.N_CHANNELS} channels on this {self._product}"
                + (
                    f" and this bench (daq.max_rate {self._max_rate_Hz:g} S/s)"
                    if self._max_rate_Hz is not None
                    else ""
                )
            )
        self.safe_state()
        nidaqmx = self._nidaqmx
        constants = nidaqmx.constants
        terminal = getattr(constants.TerminalConfiguration, TERMINAL_CONFIGS[self.terminal_config])
        try:
            task = nidaqmx.Task()
        except Exception as exc:  # NI-DAQmx itself refused (its service, its memory)
            raise InstrumentError(
                f"NI-DAQ {self.device}: cannot create a task: {self._explain(exc, config)}"
            ) from None
        try:
            for chan, rng in (
                (config.velocity_channel, config.velocity_range_V),
                (config.reference_channel, config.reference_range_V),
            ):
                task.ai_channels.add_ai_voltage_chan(
                    chan, terminal_config=terminal, min_val=-rng, max_val=rng
                )
            task.timing.cfg_samp_clk_timing(
                config.sample_rate_Hz,
                sample_mode=constants.AcquisitionType.FINITE,
                samps_per_chan=config.n_samples,
            )
            if config.n_pretrigger > 0:
                task.triggers.reference_trigger.cfg_dig_edge_ref_trig(
                    config.trigger_source,
                    pretrigger_samples=config.n_pretrigger,
                    trigger_edge=constants.Edge.RISING,
                )
            else:
                task.triggers.start_trigger.cfg_dig_edge_start_trig(
                    config.trigger_source, trigger_edge=constants.Edge.RISING
                )
            task.control(constants.TaskMode.TASK_COMMIT)
            rate = float(task.timing.samp_clk_rate)
        except Exception as exc:
            try:
                task.close()
            except Exception as close_exc:
                log.warning("NI-DAQ %s: clearing the refused task: %s", self.device, close_exc)
            raise InstrumentError(
                f"NI-DAQ {self.device}: configuration refused: {self._explain(exc, config)}"
            ) from None
        self._task, self._config, self._rate_Hz = task, config, rate
        self._running = False
        return rate

    def arm(self) -> None:
        """Start the committed task; with pretrigger samples, return once the device holds them
        (a trigger before that would be ignored)."""
        if self._task is None or self._config is None or self._rate_Hz is None:
            raise InstrumentError(f"NI-DAQ {self.device}: configure before arming")
        self._stop()  # a record that was never read (an abort between arm and read)
        try:
            self._task.start()
        except Exception as exc:
            self._forget_if_invalid(exc)
            raise InstrumentError(
                f"NI-DAQ {self.device}: could not start the acquisition: {self._explain(exc)}"
            ) from None
        self._running = True
        if self._config.n_pretrigger > 0:
            self._wait_pretrigger(self._config.n_pretrigger, self._rate_Hz)

    def _wait_pretrigger(self, n_pre: int, rate_Hz: float) -> None:
        expected_s = n_pre / rate_Hz
        deadline = self._clock.now() + 2.0 * expected_s + 1.0
        while True:
            try:
                got = int(self._task.in_stream.total_samp_per_chan_acquired)
            except Exception as exc:
                self._stop()
                self._forget_if_invalid(exc)
                raise InstrumentError(
                    f"NI-DAQ {self.device}: pretrigger progress unreadable: {self._explain(exc)}"
                ) from None
            if got >= n_pre:
                return
            if self._clock.now() > deadline:
                self._stop()
                raise InstrumentTimeout(
                    f"NI-DAQ {self.device}: {got} of {n_pre} pretrigger samples acquired after "
                    f"{2.0 * expected_s + 1.0:.3g} s: check the sample clock of the device"
                )
            self._clock.sleep(max((n_pre - got) / rate_Hz, 1e-4))

    def read(self) -> Acquisition:
        """Wait (up to the configured timeout) for the triggered record. The task is stopped
        afterwards, also on a timeout, and stays configured: the next :meth:`arm` acquires."""
        if self._task is None or self._config is None or self._rate_Hz is None:
            raise InstrumentError(f"NI-DAQ {self.device}: configure and arm before reading")
        if not self._running:
            raise InstrumentError(f"NI-DAQ {self.device}: arm before reading")
        cfg = self._config
        try:
            data = self._task.read(
                number_of_samples_per_channel=cfg.n_samples, timeout=cfg.timeout_s
            )
        except Exception as exc:
            self._stop()
            self._forget_if_invalid(exc)
            if _error_code(exc) == SAMPLES_NOT_YET_AVAILABLE:
                raise InstrumentTimeout(
                    f"NI-DAQ {self.device}: no record within {cfg.timeout_s:g} s: "
                    f"{self._explain(exc)}"
                ) from None
            raise InstrumentError(
                f"NI-DAQ {self.device}: read failed: {self._explain(exc)}"
            ) from None
        self._stop()
        arr = np.asarray(data, dtype=np.float64)
        if arr.shape != (self.N_CHANNELS, cfg.n_samples):
            raise InstrumentError(
                f"NI-DAQ {self.device}: read {arr.shape} samples, expected "
                f"({self.N_CHANNELS}, {cfg.n_samples})"
            )
        return Acquisition(
            sample_rate_Hz=self._rate_Hz,
            velocity_V=arr[0].copy(),
            reference_V=arr[1].copy(),
            n_pretrigger=cfg.n_pretrigger,
            meta={"device": self.device, "product": self._product},
        )

    def _stop(self) -> None:
        """Stop a running task back to its committed state (never raises)."""
        if self._task is not None and self._running:
            try:
                self._task.stop()
            except Exception as exc:
                log.warning("NI-DAQ %s: stopping the task: %s", self.device, exc)
                self._forget_if_invalid(exc)
        self._running = False

    def _forget_if_invalid(self, exc: BaseException) -> None:
        """A task the driver reports invalid is gone: forget it (never stop or clear it)."""
        if _error_code(exc) == INVALID_TASK:
            self._task = None
            self._running = False

    def snapshot(self) -> dict[str, Any]:
        cfg = self._config
        return {
            "model": f"NI {self._product}",
            "device": self.device,
            "terminal_config": self.terminal_config,
            "max_rate_per_channel_Hz": self.max_rate_per_channel_Hz(),
            "sample_rate_Hz": self._rate_Hz,
            "requested_rate_Hz": None if cfg is None else cfg.sample_rate_Hz,
            "n_samples": None if cfg is None else cfg.n_samples,
            "n_pretrigger": None if cfg is None else cfg.n_pretrigger,
            "channels": None if cfg is None else [cfg.velocity_channel, cfg.reference_channel],
            "trigger_source": None if cfg is None else cfg.trigger_source,
        }

    def safe_state(self) -> None:
        """Stop and clear the task; never raises, and never touches a cleared task."""
        task, self._task = self._task, None
        if task is None:
            self._running = False
            return
        if self._running:
            try:
                task.stop()
            except Exception as exc:
                log.warning("NI-DAQ %s: stopping the task: %s", self.device, exc)
        self._running = False
        try:
            task.close()
        except Exception as exc:
            log.warning("NI-DAQ %s: clearing the task: %s", self.device, exc)

    def close(self) -> None:
        self.safe_state()
