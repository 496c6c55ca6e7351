"""Emulated Polytec OFV-5000 controller + OFV-534 head (``Get``/``Set``/``GetDevInfo`` grammar).

Names follow :class:`instruments.polytec.PolytecSettings` defaults. State for the world:
:attr:`range_name`, :meth:`sensitivity_m_per_s_per_V`, :attr:`signal_level` (0..1, settable;
the world sets it from the spot position), :attr:`delay_s`, :attr:`bandwidth_Hz`. Faults:
:meth:`lose_signal`, :attr:`responsive`.
"""

from __future__ import annotations

from instruments.polytec import parse_sensitivity

__all__ = ["DEFAULT_RANGES", "PolytecEmulator"]

#: range name -> signal delay (s) of the decoder
DEFAULT_RANGES: dict[str, float] = {
    "VD-09 1mm/s/V": 7.3e-6,
    "VD-09 5mm/s/V": 7.3e-6,
    "VD-09 10mm/s/V": 7.3e-6,
    "VD-09 50mm/s/V": 7.3e-6,
    "VD-09 100mm/s/V": 7.3e-6,
}


class PolytecEmulator:
    """Answers ``Get,<dev>,<n>,<prop>`` with the value, ``Set`` silently, errors ``Error ...``."""

    def __init__(
        self,
        *,
        range_name: str = "VD-09 10mm/s/V",
        ranges: dict[str, float] | None = None,
        bandwidth_Hz: float = 100e3,
        level_full_scale: float = 100.0,
        controller: str = "OFV-5000",
        head: str = "OFV-534",
    ) -> None:
        self.ranges = dict(ranges or DEFAULT_RANGES)
        if range_name not in self.ranges:
            self.ranges[range_name] = 7.3e-6
        self.range_name = range_name
        self.bandwidth_Hz = bandwidth_Hz
        self.level_full_scale = level_full_scale
        self.signal_level = 0.8
        self.controller = controller
        self.head = head
        self.autofocus_count = 0
        self.responsive = True
        self.commands: list[str] = []

    @property
    def delay_s(self) -> float:
        return self.ranges[self.range_name]

    def sensitivity_m_per_s_per_V(self) -> float:
        return parse_sensitivity(self.range_name)

    def lose_signal(self) -> None:
        self.signal_level = 0.0

    def _get(self, dev: str, prop: str) -> str:
        if dev == "VelocityDecoder":
            if prop == "Range":
                return self.range_name
            if prop == "LowPassFilter":
                return f"{self.bandwidth_Hz / 1e3:g}kHz"
            if prop == "SignalDelay":
                return f"{self.delay_s * 1e6:g}us"
        if dev == "SensorHead" and prop == "SignalLevel":
            return f"{round(self.signal_level * self.level_full_scale):d}"
        return "Error: unknown property"

    def handle(self, message: bytes) -> str | None:
        text = message.decode("ascii", "replace").strip()
        self.commands.append(text)
        parts = [p.strip() for p in text.split(",")]
        verb = parts[0]
        if verb == "GetDevInfo" and len(parts) == 4 and parts[3] == "Name":
            return {"Controller": self.controller, "SensorHead": self.head}.get(
                parts[1], "Error: unknown device"
            )
        if verb == "Get" and len(parts) == 4:
            return self._get(parts[1], parts[3])
        if verb == "Set" and len(parts) == 5:
            dev, prop, value = parts[1], parts[3], parts[4]
            if dev == "VelocityDecoder" and prop == "Range" and value in self.ranges:
                self.range_name = value
            elif dev == "SensorHead" and prop == "AutoFocus" and value == "Start":
                self.autofocus_count += 1
            return None
        return "Error: syntax"
