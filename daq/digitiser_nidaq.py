"""NI-DAQ digitiser (nidaqmx): finite, hardware-triggered two-channel acquisition.

``nidaqmx`` imports without NI's driver and fails on first use; :class:`NidaqDigitiser`
checks the driver when constructed and raises :class:`DriverNotInstalledError` with one line.
"""

from __future__ import annotations

import logging
from typing import Any

import numpy as np

from instruments.errors import (
    DriverNotInstalledError,
    InstrumentError,
    InstrumentTimeout,
    LimitError,
)
from instruments.interfaces import Acquisition, AcquisitionConfig

__all__ = ["NidaqDigitiser"]

log = logging.getLogger(__name__)


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
        Aggregate rate ceiling (S/s, all channels); default: the device's
        ``ai_max_multi_chan_rate`` (or single-channel max x channels).
    """

    def __init__(self, device: str = "Dev1", *, max_rate_Hz: float | None = None) -> None:
        self._nidaqmx = _load_nidaqmx()
        self.device = device
        self._max_rate_Hz = max_rate_Hz
        self._task: Any = None
        self._config: AcquisitionConfig | None = None
        self._rate_Hz: float | None = None
        try:
            self._dev = self._nidaqmx.system.Device(device)
            self._product = str(self._dev.product_type)
        except Exception as exc:
            raise InstrumentError(f"NI-DAQ {device}: device not found ({exc})") from None

    def aggregate_max_rate_Hz(self, n_channels: int = 2) -> float:
        """Rate x channels ceiling in S/s."""
        if self._max_rate_Hz is not None:
            return self._max_rate_Hz
        try:
            return float(self._dev.ai_max_multi_chan_rate) * n_channels
        except Exception:
            return float(self._dev.ai_max_single_chan_rate)

    def configure(self, config: AcquisitionConfig) -> float:
        """Create the finite task; returns the coerced per-channel rate (S/s) read back."""
        limit = self.aggregate_max_rate_Hz(2)
        if config.sample_rate_Hz * 2 > limit:
            raise LimitError(
                f"NI-DAQ {self.device}: {config.sample_rate_Hz:g} S/s x 2 channels exceeds the "
                f"device maximum {limit:g} S/s"
            )
        self.safe_state()
        constants = self._nidaqmx.constants
        task = self._nidaqmx.Task()
        try:
            for chan, rng in (
                (config.velocity_channel, config.velocity_range_V),
                (config.reference_channel, config.reference_range_V),
            ):
                task.ai_channels.add_ai_voltage_chan(chan, min_val=-rng, max_val=rng)
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
            rate = float(task.timing.samp_clk_rate)
        except Exception as exc:
            task.close()
            raise InstrumentError(f"NI-DAQ {self.device}: configuration refused ({exc})") from None
        self._task, self._config, self._rate_Hz = task, config, rate
        return rate

    def arm(self) -> None:
        if self._task is None:
            raise InstrumentError(f"NI-DAQ {self.device}: configure before arming")
        self._task.start()

    def read(self) -> Acquisition:
        if self._task is None or self._config is None or self._rate_Hz is None:
            raise InstrumentError(f"NI-DAQ {self.device}: configure and arm before reading")
        cfg = self._config
        try:
            data = self._task.read(
                number_of_samples_per_channel=cfg.n_samples, timeout=cfg.timeout_s
            )
        except Exception as exc:
            self.safe_state()
            if "timeout" in str(exc).lower() or "-200284" in str(exc):
                raise InstrumentTimeout(
                    f"NI-DAQ {self.device}: no trigger/data within {cfg.timeout_s:g} s"
                ) from None
            raise InstrumentError(f"NI-DAQ {self.device}: read failed ({exc})") from None
        finally:
            try:
                self._task.stop()
            except Exception:
                pass
        arr = np.asarray(data, dtype=np.float64)
        return Acquisition(
            sample_rate_Hz=self._rate_Hz,
            velocity_V=arr[0].copy(),
            reference_V=arr[1].copy(),
            n_pretrigger=cfg.n_pretrigger,
            meta={"device": self.device, "product": self._product},
        )

    def snapshot(self) -> dict[str, Any]:
        cfg = self._config
        return {
            "model": f"NI {self._product}",
            "device": self.device,
            "sample_rate_Hz": self._rate_Hz,
            "requested_rate_Hz": None if cfg is None else cfg.sample_rate_Hz,
            "n_samples": None if cfg is None else cfg.n_samples,
            "n_pretrigger": None if cfg is None else cfg.n_pretrigger,
            "channels": None if cfg is None else [cfg.velocity_channel, cfg.reference_channel],
            "trigger_source": None if cfg is None else cfg.trigger_source,
        }

    def safe_state(self) -> None:
        """Stop and close the task; never raises."""
        if self._task is not None:
            try:
                self._task.close()
            except Exception as exc:
                log.warning("NI-DAQ %s: closing task failed: %s", self.device, exc)
            self._task = None

    def close(self) -> None:
        self.safe_state()
