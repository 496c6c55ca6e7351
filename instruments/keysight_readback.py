"""What a Keysight 33500B/33600A channel holds after configuration, read back and compared.

The instrument may coerce a value it was sent (clip an amplitude to what the load setting
allows, quantise an arb sample rate, refuse a load change while voltage limits are on) and
report only some of this in ``SYST:ERR?``. :func:`read_channel` asks every query the driver's
configuration has (``SOURn:FUNC?``, ``SOURn:VOLT?`` ...), parses the reply as the 33500 Series
Operating and Service Guide gives it, and compares it with the request:

===============  =====================================  =====================================
reply kind       example                                 parsed as
===============  =====================================  =====================================
number (NR3)     ``+1.000000000000000E+00``              float; ``OUTPn:LOAD?`` ``9.9E+37``
                                                         (and above) is high Z, ``inf``
boolean          ``1`` / ``0``                           True / False
word             ``ARB``, ``TRIG``, ``BUS``, ``CH1``     upper-case short form
string           ``"BIAFC1"``                            text between the quotes
===============  =====================================  =====================================

Tolerances (stated in every mismatch message): voltages (amplitude, offset, limits)
0.1 % of the request + 0.1 mV, so the instrument's own resolution is accepted while a clipped
value is not; the arb sample rate 1e-6 relative (the carrier is the protocol's to 1 ppm);
burst count, load, words, booleans and names exactly. An arb name read back with a memory
prefix (``"VOLATILE:BIAFC1"`` / ``"INT:\\BIAFC1"``) names the same waveform.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

from instruments.errors import ReplyError

__all__ = ["HIGH_Z_OHM", "ChannelReadback", "ChannelRequest", "read_channel"]

#: a load reply at or above this is "high impedance" (the instrument answers 9.9E+37 for INF)
HIGH_Z_OHM = 9.9e37
#: voltage tolerance: relative part and absolute part (V)
V_REL, V_ABS = 1e-3, 1e-4
#: arb sample-rate tolerance, relative
SRAT_REL = 1e-6


@dataclass(frozen=True)
class ChannelRequest:
    """What the driver sent to channel ``n`` (SI units, words as sent)."""

    arb_name: str
    sample_rate_Hz: float
    amplitude_Vpp: float
    offset_V: float
    limit_high_V: float
    limit_low_V: float
    trigger_source: str
    burst_cycles: int = 1
    function: str = "ARB"
    arb_filter: str = "NORM"
    load: str = "INF"
    amplitude_unit: str = "VPP"
    burst_mode: str = "TRIG"
    trigger_out_slope: str = "POS"
    byte_order: str = "SWAP"


@dataclass(frozen=True)
class ChannelReadback:
    """What channel ``n`` reports holding, parsed (the run file's record of the generator).

    Attributes
    ----------
    function, arb_name:
        ``FUNC?`` (``"ARB"``) and ``FUNC:ARB?`` (the waveform's name, quotes removed).
    sample_rate_Hz:
        ``FUNC:ARB:SRAT?`` in Sa/s.
    arb_filter:
        ``FUNC:ARB:FILT?`` (``"NORM"``: the flat-band filter between the arb's points).
    load_ohm:
        ``OUTPn:LOAD?`` in ohm, ``inf`` for high Z.
    amplitude_Vpp, amplitude_unit:
        ``VOLT?`` in the unit ``VOLT:UNIT?`` names (``"VPP"``: peak-to-peak volts).
    offset_V, limit_high_V, limit_low_V, limit_on:
        ``VOLT:OFFS?``, ``VOLT:LIM:HIGH?``, ``VOLT:LIM:LOW?`` (V) and ``VOLT:LIM:STAT?``.
    burst_mode, burst_cycles, burst_on:
        ``BURS:MODE?`` (``"TRIG"``), ``BURS:NCYC?`` (cycles of the arb per trigger), and
        ``BURS:STAT?``.
    trigger_source:
        ``TRIGn:SOUR?`` (``"BUS"``, ``"EXT"``, ``"IMM"``).
    trigger_out_source, trigger_out_slope, trigger_out_on:
        ``OUTP:TRIG:SOUR?`` (``"CH1"``), ``OUTP:TRIG:SLOP?`` (``"POS"``), ``OUTP:TRIG?``.
    byte_order:
        ``FORM:BORD?`` (``"SWAP"``: arb blocks little-endian).
    """

    function: str
    arb_name: str
    sample_rate_Hz: float
    arb_filter: str
    load_ohm: float
    amplitude_Vpp: float
    amplitude_unit: str
    offset_V: float
    limit_high_V: float
    limit_low_V: float
    limit_on: bool
    burst_mode: str
    burst_cycles: int
    burst_on: bool
    trigger_source: str
    trigger_out_source: str
    trigger_out_slope: str
    trigger_out_on: bool
    byte_order: str

    def as_json(self) -> dict[str, Any]:
        """JSON-serialisable dict; the high-Z load is written ``"INF"`` (JSON has no inf)."""
        out = asdict(self)
        out["load_ohm"] = "INF" if math.isinf(self.load_ohm) else self.load_ohm
        return out


# --- reply parsers (ValueError on anything else) ------------------------------------------
def parse_number(reply: str) -> float:
    """NR1/NR2/NR3 number (``+1.000000000000000E+00``) -> float."""
    value = float(reply.strip())
    if not math.isfinite(value):
        raise ValueError(reply)
    return value


def parse_load(reply: str) -> float:
    """``OUTPn:LOAD?`` -> ohm, ``inf`` for ``9.9E+37`` (high Z)."""
    value = parse_number(reply)
    return math.inf if value >= HIGH_Z_OHM else value


def parse_bool(reply: str) -> bool:
    """Boolean query reply ``1`` / ``0`` -> True / False."""
    text = reply.strip()
    if text in ("1", "+1"):
        return True
    if text in ("0", "+0"):
        return False
    raise ValueError(reply)


def parse_word(reply: str) -> str:
    """Character reply (``TRIG``, ``BUS``, ``CH1``) -> upper-case word."""
    text = reply.strip().upper()
    if not text or not text.replace("_", "").isalnum():
        raise ValueError(reply)
    return text


def parse_string(reply: str) -> str:
    """Quoted string reply (``"BIAFC1"``) -> the text inside the quotes, upper case."""
    text = reply.strip()
    if len(text) < 2 or text[0] != text[-1] or text[0] not in "\"'":
        raise ValueError(reply)
    return text[1:-1].upper()


def parse_count(reply: str) -> int:
    """A whole number sent as NR3 (``+1.000000000000000E+00``) -> int."""
    value = parse_number(reply)
    if value != int(value):
        raise ValueError(reply)
    return int(value)


# --- comparisons: None when it agrees, else the tolerance in words -------------------------
def _volts(req: float, got: float) -> str | None:
    return None if abs(got - req) <= V_REL * abs(req) + V_ABS else "0.1 % + 0.1 mV"


def _rate(req: float, got: float) -> str | None:
    return None if abs(got - req) <= SRAT_REL * abs(req) else "1e-6 relative"


def _same(req: Any, got: Any) -> str | None:
    return None if req == got else "exact"


def _arb_name(req: str, got: str) -> str | None:
    """The name asked for, as the guide's forms may give it back: bare, after a memory path
    (``VOLATILE:``, ``INT:\\...\\``), with a ``.ARB`` file suffix, in any case (the reply's
    exact form is not confirmed on an instrument)."""
    name, reply = req.upper(), got.upper().removesuffix(".ARB")
    return None if reply == name or reply.endswith((":" + name, "\\" + name)) else "exact"


def _load(req: str, got: float) -> str | None:
    if req.upper() in ("INF", "INFINITY"):
        return None if math.isinf(got) else "exact"
    return None if got == float(req) else "exact"


@dataclass(frozen=True)
class _Check:
    field: str
    label: str
    query: str
    parse: Callable[[str], Any]
    requested: Any
    agree: Callable[[Any, Any], str | None]
    unit: str = ""


def _checks(n: int, req: ChannelRequest) -> list[_Check]:
    """One check per setting the driver writes to channel ``n`` that has a query form."""
    s = f"SOUR{n}:"
    return [
        _Check("function", "function", f"{s}FUNC?", parse_word, req.function, _same),
        _Check("arb_name", "arb waveform", f"{s}FUNC:ARB?", parse_string, req.arb_name, _arb_name),
        _Check(
            "sample_rate_Hz",
            "arb sample rate",
            f"{s}FUNC:ARB:SRAT?",
            parse_number,
            req.sample_rate_Hz,
            _rate,
            " Sa/s",
        ),
        _Check("arb_filter", "arb filter", f"{s}FUNC:ARB:FILT?", parse_word, req.arb_filter, _same),
        _Check("load_ohm", "output load", f"OUTP{n}:LOAD?", parse_load, req.load, _load, " ohm"),
        _Check(
            "amplitude_unit",
            "amplitude unit",
            f"{s}VOLT:UNIT?",
            parse_word,
            req.amplitude_unit,
            _same,
        ),
        _Check(
            "limit_high_V",
            "voltage limit high",
            f"{s}VOLT:LIM:HIGH?",
            parse_number,
            req.limit_high_V,
            _volts,
            " V",
        ),
        _Check(
            "limit_low_V",
            "voltage limit low",
            f"{s}VOLT:LIM:LOW?",
            parse_number,
            req.limit_low_V,
            _volts,
            " V",
        ),
        _Check("limit_on", "voltage limits on", f"{s}VOLT:LIM:STAT?", parse_bool, True, _same),
        _Check("offset_V", "offset", f"{s}VOLT:OFFS?", parse_number, req.offset_V, _volts, " V"),
        _Check(
            "amplitude_Vpp",
            "amplitude",
            f"{s}VOLT?",
            parse_number,
            req.amplitude_Vpp,
            _volts,
            " Vpp",
        ),
        _Check("burst_mode", "burst mode", f"{s}BURS:MODE?", parse_word, req.burst_mode, _same),
        _Check(
            "burst_cycles",
            "burst count",
            f"{s}BURS:NCYC?",
            parse_count,
            req.burst_cycles,
            _same,
            " cycles",
        ),
        _Check("burst_on", "burst state", f"{s}BURS:STAT?", parse_bool, True, _same),
        _Check(
            "trigger_source",
            "trigger source",
            f"TRIG{n}:SOUR?",
            parse_word,
            req.trigger_source,
            _same,
        ),
        _Check(
            "trigger_out_source",
            "trigger out source",
            "OUTP:TRIG:SOUR?",
            parse_word,
            f"CH{n}",
            _same,
        ),
        _Check(
            "trigger_out_slope",
            "trigger out slope",
            "OUTP:TRIG:SLOP?",
            parse_word,
            req.trigger_out_slope,
            _same,
        ),
        _Check("trigger_out_on", "trigger out on", "OUTP:TRIG?", parse_bool, True, _same),
        _Check("byte_order", "byte order", "FORM:BORD?", parse_word, req.byte_order, _same),
    ]


def _text(value: Any, unit: str) -> str:
    if isinstance(value, bool):
        return "ON" if value else "OFF"
    if isinstance(value, float):
        return ("INF" if math.isinf(value) else f"{value:.10g}") + unit
    return f"{value}{unit}"


def read_channel(
    query: Callable[[str], str], name: str, n: int, request: ChannelRequest
) -> tuple[ChannelReadback, list[str]]:
    """Ask channel ``n`` every setting of ``request``; returns what it holds and the
    mismatches, each ``"channel 1 amplitude: requested 16 Vpp, read back 10 Vpp (tolerance
    0.1 % + 0.1 mV)"``. An unreadable reply raises :class:`ReplyError` naming ``name``, the
    query and the reply."""
    values: dict[str, Any] = {}
    mismatches: list[str] = []
    for c in _checks(n, request):
        raw = query(c.query)
        try:
            got = c.parse(raw)
        except ValueError:
            raise ReplyError(
                f"{name}: channel {n} {c.label}: unreadable {c.query} reply {raw!r}"
            ) from None
        values[c.field] = got
        tol = c.agree(c.requested, got)
        if tol is not None:
            mismatches.append(
                f"channel {n} {c.label}: requested {_text(c.requested, c.unit)}, read back "
                f"{_text(got, c.unit)} (tolerance {tol})"
            )
    return ChannelReadback(**values), mismatches
