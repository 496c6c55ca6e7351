"""Polytec OFV-5000 vibrometer controller with an OFV-534 sensor head (RS-232, 115200 8N1).

Grammar (Polytec "RS-232 Interface Commands", OFV-5000 user manual): ``Get,<Device>,<n>,<Item>``
answers the current value, ``Set,<Device>,<n>,<Item>,<Value>`` answers nothing, and
``GetDevInfo,<Device>,<n>,<Item>`` lists what is possible. Devices: ``Controller``,
``SensorHead``, ``Interface`` (echo, baud rate) and the decoders, ``VeloDec,<n>`` (velocity) and
``DisplDec,<n>`` (displacement), numbered per controller (a VD-09 is often ``VeloDec,1``). The
decoder's range reads e.g. ``50mm/s/V``; ``MaxFreq`` its upper frequency for that range,
``SignalDelay`` its transit delay (e.g. ``7.3us``).

Every command is one entry of a table (:data:`DEFAULT_COMMANDS`), data in one place; a bench
file overrides entries (``vibrometer: commands: {range_get: "Get,VeloDec,0,Range", ...}``)
where its controller differs. At connect the interface echo is switched off and read back
(an echoing controller sends each command line back before its reply; echoed lines are
skipped either way), and every setting is read back after it is set.
"""

from __future__ import annotations

import logging
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from instruments.errors import InstrumentError, LimitError, ReplyError, SignalLostError
from instruments.interfaces import Transport

__all__ = [
    "DEFAULT_COMMANDS",
    "VELOCITY_RANGES",
    "LevelAboveFullScale",
    "PolytecSettings",
    "PolytecVibrometer",
    "parse_sensitivity",
    "parse_si_value",
    "range_max_frequency_Hz",
    "velocity_range_error",
]

#: The RS-232 command table: key -> command (``{value}`` where a value is sent). Entries
#: marked "unconfirmed" are not in the public command lists; confirm them on the controller
#: (``GetDevInfo``) and override them in the bench file. ``None``: not available.
DEFAULT_COMMANDS: dict[str, str | None] = {
    "controller_name": "Get,Controller,0,Name",
    "controller_version": "Get,Controller,0,Version",
    "head_name": "Get,SensorHead,0,Name",
    "echo_set": "Set,Interface,0,Echo,{value}",
    "echo_get": "Get,Interface,0,Echo",
    "decoder_name": "Get,VeloDec,1,Name",
    "range_get": "Get,VeloDec,1,Range",
    "range_set": "Set,VeloDec,1,Range,{value}",
    "max_frequency_get": "Get,VeloDec,1,MaxFreq",
    "signal_delay_get": "Get,VeloDec,1,SignalDelay",
    "low_pass_get": None,  # unconfirmed name: a velocity decoder's output filter, if any
    # unconfirmed: not in the manual's public command list; the form two independent
    # third-party programs for the OFV-5000 (with a VD-09) use, answered by an integer
    "signal_level_get": "Get,SignalLevel,0,Value",
    "autofocus_start": "Set,SensorHead,0,AutoFocus,Search",
    "autofocus_result": "Get,SensorHead,0,AutoFocusResult",
}
#: replies that mean "no such item here"
_NOT_AVAILABLE = ("ERROR", "NOT AVAILABLE", "NOT INSTALLED")

log = logging.getLogger(__name__)

_DECODER_RE = re.compile(r"^([A-Za-z]{2}-\d+\w*)\s+(.+)$")


#: The velocity decoders known on the OFV-5000 (with the OFV-534 head): decoder -> its ranges
#: (sensitivity, mm/s/V) -> the range's upper frequency (Hz), ``None`` where no source gives it.
#: The ranges are those a lab's OFV-5000 software offers (the PALab PLACE project's Polytec
#: plugin: VD-09 5 mm/s/V to 1 m/s/V, from 20 mm/s/V also as an "LP" low-pass variant; VD-08
#: 0.2 to 50 mm/s/V); before, the VD-09 had the VD-08's 1 and 2 mm/s/V and lacked 200 mm/s/V to
#: 1 m/s/V. The frequencies up to 100 mm/s/V are the earlier table's, unconfirmed. A range not
#: listed here is refused before anything is connected; the controller's own ``MaxFreq`` is
#: what a run records.
VELOCITY_RANGES: dict[str, dict[float, float | None]] = {
    "VD-09": {
        5: 500e3,
        10: 1.5e6,
        20: 1.5e6,
        50: 2.5e6,
        100: 2.5e6,
        200: None,
        500: None,
        1000: None,
    },
    "VD-08": {0.2: None, 0.5: None, 1: None, 2: None, 5: None, 10: None, 20: None, 50: None},
}
#: a range with the decoder's low-pass filter on (``"50mm/s/V LP"``): the same sensitivity
_LOW_PASS = re.compile(r"\s*LP$", re.IGNORECASE)


def _range_parts(range_name: str) -> tuple[str, float] | None:
    """``"VD-09 50mm/s/V"`` -> ``("VD-09", 50.0)`` (mm/s/V); ``None`` when unreadable."""
    m = _DECODER_RE.match(range_name.strip())
    if m is None:
        return None
    try:
        return m.group(1), parse_sensitivity(m.group(2)) * 1e3
    except ReplyError:
        return None


def _allowed_text() -> str:
    return "; ".join(
        f"{d}: " + ", ".join(f"{r:g}" for r in sorted(table)) + " mm/s/V"
        for d, table in VELOCITY_RANGES.items()
    )


def velocity_range_error(range_name: str) -> str | None:
    """Why ``range_name`` (``"VD-09 50mm/s/V"``) is not a range of a known decoder, or
    ``None``; the message lists the ranges there are."""
    parts = _range_parts(range_name)
    if parts is None:
        return (
            f"{range_name!r} is not '<decoder> <range>' (e.g. 'VD-09 50mm/s/V'); "
            f"ranges: {_allowed_text()}"
        )
    decoder, mm_s_V = parts
    table = VELOCITY_RANGES.get(decoder)
    if table is None:
        return f"decoder {decoder!r} is not one this software knows ({_allowed_text()})"
    if _LOW_PASS.search(range_name) and (decoder != "VD-09" or mm_s_V < 20):
        return f"{range_name!r}: low-pass ('LP') ranges are the VD-09's from 20 mm/s/V"
    if not any(math.isclose(mm_s_V, r, rel_tol=1e-9) for r in table):
        shown = ", ".join(f"{r:g}" for r in sorted(table))
        return f"{range_name!r} is not a range of the {decoder}; its ranges: {shown} mm/s/V"
    return None


def range_max_frequency_Hz(range_name: str) -> float | None:
    """The upper frequency (Hz) of a known decoder range, or ``None`` (unknown, or a low-pass
    range, whose filter's corner no source gives)."""
    parts = _range_parts(range_name)
    if parts is None or _LOW_PASS.search(range_name):
        return None
    table = VELOCITY_RANGES.get(parts[0], {})
    return next((f for r, f in table.items() if math.isclose(parts[1], r, rel_tol=1e-9)), None)


def parse_sensitivity(range_name: str) -> float:
    """``"VD-09 10mm/s/V"`` (or ``"10 mm/s/V"``) -> 0.01 (m/s)/V, read with the project's unit
    registry (:mod:`instruments.units`). :class:`ReplyError` if it names no velocity per volt."""
    from instruments.units import UnitError, parse_quantity

    m = _DECODER_RE.match(range_name.strip())
    text = _LOW_PASS.sub("", m.group(2) if m else range_name)
    try:
        value = parse_quantity(text.strip(), "velocity_per_volt")
    except UnitError:
        raise ReplyError(
            f"cannot read a sensitivity (e.g. '10mm/s/V') from range {range_name!r}"
        ) from None
    if not value > 0:
        raise ReplyError(f"range {range_name!r} gives a non-positive sensitivity")
    return value


def parse_si_value(text: str, unit: str) -> float:
    """``"100kHz"``/``"100 kHz"`` with ``unit="Hz"`` -> 1e5 (read with the project's unit
    registry, in ``unit``: ``"Hz"`` or ``"s"``); a bare number is taken as SI."""
    from instruments.units import DIMENSIONS, UnitError, parse_quantity

    s = text.strip()
    if re.fullmatch(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?", s):
        return float(s)
    dimension = next(k for k, d in DIMENSIONS.items() if d.unit == unit)
    try:
        return parse_quantity(s, dimension)
    except UnitError:
        raise ReplyError(f"cannot read a value in {unit} from {text!r}") from None


class LevelAboveFullScale(ReplyError):
    """A signal-level reading above the bench file's ``vibrometer.level_full_scale``: the scale
    is wrong for this controller (``reading`` as read, ``full_scale``)."""

    def __init__(self, name: str, reading: str, full_scale: float) -> None:
        self.reading, self.full_scale = reading, full_scale
        super().__init__(
            f"{name}: signal level {reading} is above the full scale {full_scale:g} "
            "(vibrometer.level_full_scale in the bench file): set it to this controller's "
            "reading with the beam on a good target"
        )


@dataclass(frozen=True)
class PolytecSettings:
    """Command table overrides and thresholds.

    Attributes
    ----------
    commands:
        Entries of :data:`DEFAULT_COMMANDS` that differ on this controller (e.g. the decoder's
        number); a key not in the table is refused.
    level_full_scale:
        Full scale of the signal-level reading (level / full scale = 0..1); a reading above
        it is a :class:`ReplyError`, not clipped to 1 (the scale is not in Polytec's public
        command list: the bench file gives it).
    min_signal_level:
        Below this (0..1) :meth:`PolytecVibrometer.check_signal` raises
        :class:`SignalLostError`.
    autofocus_timeout_s, autofocus_poll_s:
        How long autofocus may take, and the polling period of its result (s).
    """

    commands: Mapping[str, str | None] = field(default_factory=dict)
    level_full_scale: float = 100.0
    min_signal_level: float = 0.2
    autofocus_timeout_s: float = 30.0
    autofocus_poll_s: float = 0.5

    def __post_init__(self) -> None:
        unknown = sorted(set(self.commands) - set(DEFAULT_COMMANDS))
        if unknown:
            raise LimitError(
                f"vibrometer commands: unknown entries {unknown}; known: "
                + ", ".join(DEFAULT_COMMANDS)
            )
        if not (math.isfinite(self.level_full_scale) and self.level_full_scale > 0):
            raise LimitError(f"level_full_scale must be > 0, got {self.level_full_scale!r}")
        if not 0 <= self.min_signal_level <= 1:
            raise LimitError(f"min_signal_level must be in [0, 1], got {self.min_signal_level!r}")

    def table(self) -> dict[str, str | None]:
        """The command table in force (defaults with the overrides)."""
        return {**DEFAULT_COMMANDS, **dict(self.commands)}


class PolytecVibrometer:
    """OFV-5000 controller on a :class:`Transport` (implements ``Vibrometer``)."""

    def __init__(self, transport: Transport, settings: PolytecSettings | None = None) -> None:
        self.transport = transport
        self.settings = settings or PolytecSettings()
        self.commands = self.settings.table()
        self._identity: str | None = None
        self._firmware: str | None = None
        self._sent: str | None = None

    # --- wire ---------------------------------------------------------------------------
    def _command(self, key: str, value: str | None = None) -> str:
        template = self.commands[key]
        if template is None:
            raise ReplyError(
                f"{self.transport.name}: no command for {key!r} on this controller "
                "(set vibrometer: commands: in the bench file)"
            )
        return template.format(value=value) if value is not None else template

    def _query(self, key: str) -> str:
        cmd = self._command(key)
        reply = self.transport.query(cmd).strip()
        for _ in range(4):  # an echoing controller sends the command line(s) back first
            if reply not in (cmd, self._sent):
                break
            reply = self.transport.read().strip()
        self._sent = None
        if not reply or reply.upper().startswith(_NOT_AVAILABLE):
            raise ReplyError(f"{self.transport.name}: {cmd!r} answered {reply!r}")
        return reply

    def _set(self, key: str, value: str, readback: str) -> None:
        """``Set`` then read back with ``readback``; :class:`ReplyError` when it differs."""
        cmd = self._command(key, value)
        self.transport.write(cmd)
        self._sent = cmd
        got = self._query(readback)
        if got.replace(" ", "").lower() != value.replace(" ", "").lower():
            raise ReplyError(
                f"{self.transport.name}: {cmd!r} reads back {got!r} ({readback}), not {value!r}"
            )

    # --- identity -----------------------------------------------------------------------
    def connect(self) -> str:
        """Echo off (read back; skipped when the table has no ``echo_set``), then
        :meth:`identify`."""
        if self.commands["echo_set"] is not None:
            self._set("echo_set", "Off", "echo_get")
        return self.identify()

    def identify(self) -> str:
        """``"<controller> / <head>"`` (e.g. ``"OFV-5000 / OFV-534"``)."""
        self._identity = f"{self._query('controller_name')} / {self._query('head_name')}"
        try:
            self._firmware = self._query("controller_version")
        except ReplyError:
            self._firmware = None
        return self._identity

    def identity(self) -> dict[str, Any]:
        """Controller, head, firmware, decoder and range as read (for ``biafc check``)."""
        return {
            "identity": self._identity or self.identify(),
            "firmware": self._firmware,
            "velocity_range": self.velocity_range(),
        }

    # --- decoder ------------------------------------------------------------------------
    def velocity_range(self) -> str:
        """``"<decoder> <range>"``, e.g. ``"VD-09 50mm/s/V"``."""
        return f"{self._query('decoder_name')} {self._query('range_get')}"

    def set_velocity_range(self, name: str) -> None:
        """Select range ``name`` (``"VD-09 10mm/s/V"`` or ``"10mm/s/V"``) on the table's
        decoder; the decoder's name must match when given, and the range is read back."""
        parse_sensitivity(name)  # refuse a name we could not use, before sending
        m = _DECODER_RE.match(name.strip())
        decoder, value = (m.group(1), m.group(2)) if m else ("", name.strip())
        if decoder:
            have = self._query("decoder_name")
            if have.replace(" ", "").upper() != decoder.replace(" ", "").upper():
                raise ReplyError(
                    f"{self.transport.name}: range {name!r} asks for decoder {decoder}, "
                    f"{self._command('decoder_name')!r} is {have!r}: set vibrometer: commands: "
                    "in the bench file for this controller's decoder number"
                )
        self._set("range_set", value, "range_get")

    def sensitivity_m_per_s_per_V(self) -> float:
        return parse_sensitivity(self._query("range_get"))

    def bandwidth_Hz(self) -> float:
        """The decoder's upper frequency for its range (``MaxFreq``), or the low-pass filter's
        cut-off when the table has a command for it."""
        key = "low_pass_get" if self.commands["low_pass_get"] is not None else "max_frequency_get"
        return parse_si_value(self._query(key), "Hz")

    def signal_delay_s(self) -> float:
        return parse_si_value(self._query("signal_delay_get"), "s")

    def signal_level(self) -> float:
        s = self.settings
        raw = self._query("signal_level_get")
        try:
            value = float(raw)
        except ValueError:
            raise ReplyError(
                f"{self.transport.name}: signal level {raw!r} is not a number"
            ) from None
        if value > s.level_full_scale:
            # clipping it to 1 would pass every point on a controller with a larger scale
            raise LevelAboveFullScale(self.transport.name, raw, s.level_full_scale)
        return max(value / s.level_full_scale, 0.0)

    def check_signal(self) -> float:
        """The signal level; :class:`SignalLostError` below ``min_signal_level``."""
        level = self.signal_level()
        if level < self.settings.min_signal_level:
            raise SignalLostError(
                f"{self.transport.name}: signal level {level:.2f} below "
                f"{self.settings.min_signal_level:.2f}: refocus or clean the target"
            )
        return level

    def autofocus(self, clock: Any = None) -> bool:
        """Start autofocus and wait for ``Found``; ``False`` when the table has no autofocus.
        ``clock`` (``now``/``sleep``) paces the polling; default: the system clock."""
        if self.commands["autofocus_start"] is None:
            return False
        from instruments.clock import SystemClock

        clk = clock or SystemClock()
        self.transport.write(self._command("autofocus_start"))
        self._sent = self._command("autofocus_start")
        t_end = clk.now() + self.settings.autofocus_timeout_s
        while True:
            result = self._query("autofocus_result")
            if result.strip().lower() == "found":
                return True
            if clk.now() > t_end:
                raise ReplyError(
                    f"{self.transport.name}: autofocus not found within "
                    f"{self.settings.autofocus_timeout_s:g} s (last {result!r})"
                )
            clk.sleep(self.settings.autofocus_poll_s)

    def snapshot(self) -> dict[str, Any]:
        """Identity, firmware, range, sensitivity, bandwidth, delay, signal level (SI)."""
        range_name = self.velocity_range()
        return {
            "model": "Polytec OFV-5000",
            "identity": self._identity or self.identify(),
            "firmware": self._firmware,
            "resource": self.transport.name,
            "velocity_range": range_name,
            "sensitivity_m_per_s_per_V": parse_sensitivity(range_name),
            "bandwidth_Hz": self.bandwidth_Hz(),
            "signal_delay_s": self.signal_delay_s(),
            "signal_level": self.signal_level(),
            "commands": dict(self.settings.commands),
        }

    def safe_state(self) -> None:
        """Nothing drives or moves in a vibrometer: no-op (kept for the interface)."""

    def close(self) -> None:
        try:
            self.transport.close()
        except InstrumentError as exc:  # pragma: no cover - closing a dead link
            log.warning("%s: close failed: %s", self.transport.name, exc)
