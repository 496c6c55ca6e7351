"""Polytec OFV-5000-class vibrometer controller with an OFV-534 sensor head (RS-232).

Command grammar: ``Get,<Device>,<n>,<Property>`` (reply: the value), ``Set,<Device>,<n>,
<Property>,<Value>`` (no reply; every Set is read back with Get), ``GetDevInfo,<Device>,<n>,
<Item>``. Device and property names differ between firmware versions and decoder boards: every
name is a field of :class:`PolytecSettings` (defaults are this project's assumptions, to be
confirmed with ``GetDevInfo`` on the bench), not a constant baked in here.
"""

from __future__ import annotations

import logging
import math
import re
from dataclasses import dataclass
from typing import Any

from instruments.errors import InstrumentError, LimitError, ReplyError, SignalLostError
from instruments.interfaces import Transport

__all__ = ["PolytecSettings", "PolytecVibrometer", "parse_sensitivity", "parse_si_value"]

log = logging.getLogger(__name__)

_PREFIX = {"": 1.0, "k": 1e3, "M": 1e6, "m": 1e-3, "u": 1e-6, "µ": 1e-6, "n": 1e-9}
_SENS_RE = re.compile(r"([0-9]*\.?[0-9]+(?:[eE][+-]?\d+)?)\s*(mm|um|µm|nm|m)\s*/\s*s\s*/\s*V")
_LEN = {"m": 1.0, "mm": 1e-3, "um": 1e-6, "µm": 1e-6, "nm": 1e-9}


def parse_sensitivity(range_name: str) -> float:
    """``"VD-09 10mm/s/V"`` -> 0.01 (m/s)/V. :class:`ReplyError` if no ``<x><unit>/s/V`` in it."""
    m = _SENS_RE.search(range_name)
    if m is None:
        raise ReplyError(f"cannot read a sensitivity (e.g. '10mm/s/V') from range {range_name!r}")
    value = float(m.group(1)) * _LEN[m.group(2)]
    if not value > 0:
        raise ReplyError(f"range {range_name!r} gives a non-positive sensitivity")
    return value


def parse_si_value(text: str, unit: str) -> float:
    """``"100kHz"``/``"100 kHz"`` with ``unit="Hz"`` -> 1e5; a bare number is taken as SI."""
    s = text.strip()
    m = re.fullmatch(
        r"([+-]?[0-9]*\.?[0-9]+(?:[eE][+-]?\d+)?)\s*([kMmuµn]?)" + re.escape(unit) + "?", s
    )
    if m is None:
        raise ReplyError(f"cannot read a value in {unit} from {text!r}")
    if m.group(2) and not s.endswith(unit):
        raise ReplyError(f"cannot read a value in {unit} from {text!r}")
    return float(m.group(1)) * _PREFIX[m.group(2)]


@dataclass(frozen=True)
class PolytecSettings:
    """Device/property names (confirm with ``GetDevInfo``) and thresholds.

    Attributes
    ----------
    controller_device, head_device:
        Device names whose ``GetDevInfo,<dev>,0,Name`` identify controller and sensor head.
    decoder_device, decoder_index:
        The velocity decoder (``Get,<decoder_device>,<decoder_index>,<property>``).
    range_property, bandwidth_property, delay_property:
        Decoder properties: range name, low-pass bandwidth (Hz), signal delay (s).
    level_device, level_property, level_full_scale:
        Signal level read-out and its full scale (level / full scale = 0..1).
    autofocus_device, autofocus_property:
        Autofocus command (``Set,<dev>,0,<property>,Start``); ``None`` when the head has none.
    min_signal_level:
        Below this (0..1) :meth:`check_signal` raises :class:`SignalLostError`.
    """

    controller_device: str = "Controller"
    head_device: str = "SensorHead"
    decoder_device: str = "VelocityDecoder"
    decoder_index: int = 0
    range_property: str = "Range"
    bandwidth_property: str = "LowPassFilter"
    delay_property: str = "SignalDelay"
    level_device: str = "SensorHead"
    level_property: str = "SignalLevel"
    level_full_scale: float = 100.0
    autofocus_device: str | None = "SensorHead"
    autofocus_property: str = "AutoFocus"
    min_signal_level: float = 0.2

    def __post_init__(self) -> None:
        if not (math.isfinite(self.level_full_scale) and self.level_full_scale > 0):
            raise LimitError(f"level_full_scale must be > 0, got {self.level_full_scale!r}")
        if not 0 <= self.min_signal_level <= 1:
            raise LimitError(f"min_signal_level must be in [0, 1], got {self.min_signal_level!r}")


class PolytecVibrometer:
    """OFV-5000 controller on a :class:`Transport` (implements ``Vibrometer``)."""

    def __init__(self, transport: Transport, settings: PolytecSettings | None = None) -> None:
        self.transport = transport
        self.settings = settings or PolytecSettings()
        self._identity: str | None = None

    def _get(self, device: str, index: int, prop: str) -> str:
        cmd = f"Get,{device},{index},{prop}"
        reply = self.transport.query(cmd).strip()
        if not reply or reply.upper().startswith("ERROR"):
            raise ReplyError(f"{self.transport.name}: {cmd!r} answered {reply!r}")
        return reply

    def _set(self, device: str, index: int, prop: str, value: str) -> None:
        self.transport.write(f"Set,{device},{index},{prop},{value}")

    def _decoder(self, prop: str) -> str:
        return self._get(self.settings.decoder_device, self.settings.decoder_index, prop)

    def identify(self) -> str:
        """``"<controller> / <head>"`` from ``GetDevInfo,<dev>,0,Name``."""
        names = []
        for dev in (self.settings.controller_device, self.settings.head_device):
            cmd = f"GetDevInfo,{dev},0,Name"
            reply = self.transport.query(cmd).strip()
            if not reply or reply.upper().startswith("ERROR"):
                raise ReplyError(f"{self.transport.name}: {cmd!r} answered {reply!r}")
            names.append(reply)
        self._identity = " / ".join(names)
        return self._identity

    def velocity_range(self) -> str:
        return self._decoder(self.settings.range_property)

    def set_velocity_range(self, name: str) -> None:
        """Select decoder range ``name`` (e.g. ``"VD-09 10mm/s/V"``), read back to confirm."""
        parse_sensitivity(name)  # refuse a name we could not use, before sending
        s = self.settings
        self._set(s.decoder_device, s.decoder_index, s.range_property, name)
        got = self.velocity_range()
        if got != name:
            raise ReplyError(f"{self.transport.name}: range set to {name!r}, reads back {got!r}")

    def sensitivity_m_per_s_per_V(self) -> float:
        return parse_sensitivity(self.velocity_range())

    def bandwidth_Hz(self) -> float:
        return parse_si_value(self._decoder(self.settings.bandwidth_property), "Hz")

    def signal_delay_s(self) -> float:
        return parse_si_value(self._decoder(self.settings.delay_property), "s")

    def signal_level(self) -> float:
        s = self.settings
        raw = self._get(s.level_device, 0, s.level_property)
        try:
            value = float(raw)
        except ValueError:
            raise ReplyError(
                f"{self.transport.name}: signal level {raw!r} is not a number"
            ) from None
        return min(max(value / s.level_full_scale, 0.0), 1.0)

    def check_signal(self) -> float:
        """The signal level; :class:`SignalLostError` below ``min_signal_level``."""
        level = self.signal_level()
        if level < self.settings.min_signal_level:
            raise SignalLostError(
                f"{self.transport.name}: signal level {level:.2f} below "
                f"{self.settings.min_signal_level:.2f}: refocus or clean the target"
            )
        return level

    def autofocus(self) -> bool:
        """Start autofocus if the head has one; returns whether it was started."""
        s = self.settings
        if s.autofocus_device is None:
            return False
        self._set(s.autofocus_device, 0, s.autofocus_property, "Start")
        return True

    def snapshot(self) -> dict[str, Any]:
        """Identity, range, sensitivity, bandwidth, delay, signal level (SI)."""
        range_name = self.velocity_range()
        return {
            "model": "Polytec OFV-5000",
            "identity": self._identity or self.identify(),
            "resource": self.transport.name,
            "velocity_range": range_name,
            "sensitivity_m_per_s_per_V": parse_sensitivity(range_name),
            "bandwidth_Hz": self.bandwidth_Hz(),
            "signal_delay_s": self.signal_delay_s(),
            "signal_level": self.signal_level(),
        }

    def safe_state(self) -> None:
        """Nothing drives or moves in a vibrometer: no-op (kept for the interface)."""

    def close(self) -> None:
        try:
            self.transport.close()
        except InstrumentError as exc:  # pragma: no cover - closing a dead link
            log.warning("%s: close failed: %s", self.transport.name, exc)
