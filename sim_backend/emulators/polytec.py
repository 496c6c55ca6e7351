"""Emulated Polytec OFV-5000 controller with an OFV-534 head and a VD-09 velocity decoder.

Written from Polytec's RS-232 interface description of the OFV-5000 (as public drivers use it),
not from this project's driver: ``Get,<Device>,<n>,<Item>`` answers the value,
``Set,<Device>,<n>,<Item>,<Value>`` answers nothing, ``GetDevInfo,...`` lists the choices.
Devices: ``Controller,0`` (Name, Version), ``SensorHead,0`` (Name, AutoFocus ``Search`` ->
AutoFocusResult ``Found``), ``Interface,0`` (Echo ``On``/``Off``, BaudRate 115200) and the
velocity decoder ``VeloDec,1`` (Name ``VD-09``, Range ``50mm/s/V``, MaxFreq, SignalDelay).
With echo on (:attr:`echo`, on by default here: the strict case) every received line is sent
back before any reply. An item that does not exist answers ``Not Available``.
The signal level is ``Get,SignalLevel,0,Value``, an integer: the device ``SignalLevel`` is not in
the manual's public command list; this is the form two independent third-party programs for an
OFV-5000 with a VD-09 read. Its scale is not documented: ``level_scale`` is the reading at a
full signal (100 by default here; one of those programs draws 775 as its bar's full scale).

State for the world: :attr:`range_name` (``"VD-09 50mm/s/V"``), :attr:`delay_s`,
:meth:`sensitivity_m_per_s_per_V`, :attr:`signal_level` (0..1, settable). Faults:
:meth:`lose_signal`, :attr:`responsive`.
"""

from __future__ import annotations

import re

__all__ = ["BAUD_RATE", "VD09_RANGES", "PolytecEmulator"]

BAUD_RATE = 115200
#: VD-09 ranges as an OFV-5000 lists them (the PLACE project's plugin: 5 mm/s/V to 1 m/s/V, from
#: 20 mm/s/V also with the low-pass filter, "LP"): value -> (sensitivity (m/s)/V, MaxFreq Hz).
#: The frequencies are this emulator's assumption (no source gives them per range; 100 kHz for
#: the low-pass ones); signal delay 7.3 us
VD09_RANGES: dict[str, tuple[float, float]] = {
    "5mm/s/V": (5e-3, 500e3),
    "10mm/s/V": (10e-3, 1.5e6),
    **{
        f"{v}/V{lp}": (sens, 100e3 if lp else 2.5e6)
        for v, sens in (
            ("20mm/s", 20e-3),
            ("50mm/s", 50e-3),
            ("100mm/s", 100e-3),
            ("200mm/s", 200e-3),
            ("500mm/s", 500e-3),
            ("1m/s", 1.0),
        )
        for lp in ("", " LP")
    },
}
VD09_DELAY_S = 7.3e-6
NOT_AVAILABLE = "Not Available"


def _canonical(value: str) -> str:
    """A range as this controller spells it: no spaces, but one before ``LP``."""
    v = re.sub(r"\s", "", value)
    return v[:-2] + " LP" if v.upper().endswith("LP") else v


class PolytecEmulator:
    """One controller: ``handle(line)`` -> reply line(s) or None."""

    def __init__(
        self,
        *,
        range_name: str = "VD-09 10mm/s/V",
        decoder_index: int = 1,
        echo: bool = True,
        controller: str = "OFV-5000",
        head: str = "OFV-534",
        level_scale: int = 100,
    ) -> None:
        decoder, _, value = range_name.partition(" ")
        if decoder != "VD-09" or _canonical(value) not in VD09_RANGES:
            raise ValueError(f"emulated VD-09 has no range {range_name!r}")
        self.decoder = decoder
        self.range_value = _canonical(value)
        self.decoder_index = decoder_index
        self.echo = echo
        #: line speed (baud) the device listens at; 115200 as shipped
        self.baud_rate = BAUD_RATE
        self.signal_level = 0.8
        #: the integer read at a full signal (``signal_level`` 1.0)
        self.level_scale = level_scale
        #: the decoder's signal delay (s), settable
        self.decoder_delay_s = VD09_DELAY_S
        self.controller = controller
        self.head = head
        self.autofocus_count = 0
        self.responsive = True
        self.commands: list[str] = []

    @property
    def range_name(self) -> str:
        return f"{self.decoder} {self.range_value}"

    @property
    def delay_s(self) -> float:
        return self.decoder_delay_s

    def sensitivity_m_per_s_per_V(self) -> float:
        return VD09_RANGES[self.range_value][0]

    def lose_signal(self) -> None:
        self.signal_level = 0.0

    def _item(self, device: str, index: str, item: str) -> str | None:
        """The value of one item, None when there is no such item."""
        if device == "Controller" and index == "0":
            return {"Name": self.controller, "Version": "2.4"}.get(item)
        if device == "SignalLevel" and index == "0":
            return str(round(self.signal_level * self.level_scale)) if item == "Value" else None
        if device == "SensorHead" and index == "0":
            return {"Name": self.head, "Version": "1.1", "AutoFocusResult": "Found"}.get(item)
        if device == "Interface" and index == "0":
            return {"Name": "RS-232", "Echo": "On" if self.echo else "Off"}.get(
                item, str(self.baud_rate) if item == "BaudRate" else None
            )
        if device == "VeloDec" and index == str(self.decoder_index):
            if item == "Name":
                return self.decoder
            if item == "Range":
                return self.range_value
            if item == "MaxFreq":
                return f"{VD09_RANGES[self.range_value][1] / 1e3:g}kHz"
            if item == "SignalDelay":
                return f"{self.decoder_delay_s * 1e6:g}us"
        return None

    def _set(self, device: str, index: str, item: str, value: str) -> None:
        if device == "Interface" and index == "0" and item == "Echo" and value in ("On", "Off"):
            self.echo = value == "On"
        elif device == "VeloDec" and index == str(self.decoder_index) and item == "Range":
            if _canonical(value) in VD09_RANGES:
                self.range_value = _canonical(value)
        elif device == "SensorHead" and index == "0" and item == "AutoFocus" and value == "Search":
            self.autofocus_count += 1

    def handle(self, message: bytes) -> str | None:
        text = message.decode("ascii", "replace").strip()
        self.commands.append(text)
        echoed = [text] if self.echo else []  # the echo setting as it was when the line came in
        parts = [p.strip() for p in text.split(",")]
        reply: str | None = None
        if parts[0] == "Get" and len(parts) == 4:
            reply = self._item(parts[1], parts[2], parts[3]) or NOT_AVAILABLE
        elif parts[0] == "GetDevInfo" and len(parts) == 4:
            value = self._item(parts[1], parts[2], parts[3])
            reply = NOT_AVAILABLE if value is None else value
        elif parts[0] == "Set" and len(parts) == 5:
            self._set(parts[1], parts[2], parts[3], parts[4])
        else:
            reply = NOT_AVAILABLE
        lines = echoed + ([reply] if reply is not None else [])
        return "\n".join(lines) if lines else None
