"""Emulated Keysight 33500B/33600A: the SCPI subset the driver uses, with a real error queue.

State the simulated world reads: :attr:`KeysightEmulator.channels` (``ChannelState`` per channel:
normalised waveform samples ``[n]``, arb sample rate, amplitude Vpp, offset, load, output,
burst and trigger settings). Hooks: :attr:`trigger_hooks` (called with the tuple of channels
that fire on ``*TRG``), :attr:`responsive` (False: stops answering), :meth:`push_error`,
:attr:`late_replies` (the next n query replies miss their timeout and arrive just before the
following reply, as from an instrument that stalled), :meth:`clear` (device clear: the output
queue, late replies included, is dropped; the error queue is kept, as IEEE 488.2 says),
:attr:`stored_points` (an upload keeps only its first n points, silently: a truncated transfer).
The arbitrary waveform of ``n`` points is played in ``n / SRAT`` s (point ``k`` at ``k / SRAT``).

Queries answer as the 33500 Series Operating and Service Guide gives them ("Typical Return"):
numbers in NR3 with 15 decimals (``+1.000000000000000E+00``; ``OUTPn:LOAD?`` answers
``+9.9E+37`` for high Z), booleans ``1``/``0``, discrete settings as their upper-case short form
(``ARB``, ``TRIG``, ``BUS``, ``POS``, ``VPP``), arb names as a quoted string (``"BIAFC1"``).
From the guide's "Output Termination": the load is 1 ohm to 10 kohm or INF (default 50 ohm);
changing it rescales the displayed amplitude and offset without an error (50 ohm -> INF
doubles them); units become Vpp at high Z; and the load cannot be changed while the voltage
limits are on (here: -221 "Settings conflict", the setting kept); an amplitude or offset past
the voltage limits is clipped to them and "Settings conflict" reported. From its "BURSt
Subsystem":
with an immediate trigger a burst longer than the burst period (``BURS:INT:PER``, 10 ms after a
reset) raises the period to fit and reports "Settings conflict" (checked here as the burst,
its trigger source or its period is set).

``strict=True`` coerces instead of refusing, like the instrument: an amplitude or offset outside
what the load allows (at 50 ohm 1 mVpp to 10 Vpp, |offset| + Vpp/2 <= 5 V; twice that at high
Z) is clipped to the nearest allowed value and -222 "Data out of range" is queued; amplitude
and offset are kept to :attr:`KeysightEmulator.volt_digits` significant digits and the arb
sample rate to :attr:`KeysightEmulator.srat_digits`, silently. The digit counts are stand-ins
for the instrument's resolution (the guide states no step), so a test can make them coarse.

``DATA:ATTRibute:POINts? [<arb name>]``: "Returns the number of points in the specified arbitrary
waveform segment in INTERNAL or USB memory, or loaded into waveform memory" (the 33500B
programming reference); here the points stored under that name in the channel's volatile
memory, as an NR1 integer (``+1024``; the reply's exact form is not confirmed on an instrument),
the channel's selected arb without a name. An unknown name is refused as ``FUNC:ARB`` refuses it
(-224; the guide's error list gives no code of its own that was found).
"""

from __future__ import annotations

import math
import re
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

__all__ = ["ChannelState", "KeysightEmulator", "scpi_short"]

IDN = "Keysight Technologies,33522B,MY00000000,4.00-1.19-2.00-58-00"
MAX_HIGHZ_VPP = 20.0
MIN_HIGHZ_VPP = 2.0e-3
#: series output impedance (ohm): the displayed voltage is the open-circuit one x R / (R + 50)
OUTPUT_OHM = 50.0
MAX_SRATE = 160.0e6
QUEUE_LEN = 20
_VOWELS = set("AEIOU")
_NUM = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$")


def _arbitrary_block(raw: bytes) -> tuple[bytes, bytes]:
    """IEEE 488.2 definite-length arbitrary block (7.7.6.2): ``#``, one non-zero digit ``n``,
    ``n`` digits giving the byte count, then exactly that many bytes. Returns (payload, rest).
    Written here from the standard, not shared with the driver's encoder."""
    if raw[:1] != b"#" or len(raw) < 2 or raw[1] not in b"123456789":
        raise ValueError("not a definite-length block")
    n = raw[1] - ord("0")
    count = raw[2 : 2 + n]
    if len(count) != n or not all(c in b"0123456789" for c in count):
        raise ValueError("block byte count is not n digits")
    end = 2 + n + int(count)
    if len(raw) < end:
        raise ValueError("block shorter than its byte count")
    return raw[2 + n : end], raw[end:]


def scpi_short(token: str) -> str:
    """SCPI short form of one header node (``VOLTage`` -> ``VOLT``, ``ERRor`` -> ``ERR``)."""
    t = token.upper()
    if len(t) <= 4:
        return t
    return t[:3] if t[3] in _VOWELS else t[:4]


def _nr3(x: float) -> str:
    """NR3 as the instrument writes it: ``+1.000000000000000E+00``."""
    return f"{float(x):+.15E}"


def _digits(x: float, digits: int) -> float:
    """``x`` kept to ``digits`` significant digits."""
    return float(f"{x:.{digits}g}")


def _divider(load_ohm: float) -> float:
    """Displayed / open-circuit voltage for a load setting: R / (R + 50), 1 at high Z."""
    return 1.0 if math.isinf(load_ohm) else load_ohm / (load_ohm + OUTPUT_OHM)


class ScpiError(Exception):
    def __init__(self, code: int, message: str) -> None:
        super().__init__(f"{code},{message}")
        self.code = code
        self.message = message


#: The arb a channel holds after a reset or ``DATA:VOL:CLE`` ("Clears waveform memory for the
#: specified channel and reloads the default waveform", the programming guide)
DEFAULT_ARB = r"INT:\BUILTIN\EXP_RISE.ARB"


def _exp_rise(n: int = 256) -> NDArray[np.float64]:
    """A stand-in for the built-in EXP_RISE (its samples are not published): an exponential
    rise over the record, normalised to -1..+1."""
    rise = 1.0 - np.exp(-5.0 * np.linspace(0.0, 1.0, n))
    return 2.0 * rise / rise[-1] - 1.0


@dataclass
class ChannelState:
    """One output channel (SI units; ``waveform`` normalised to +/-1)."""

    function: str = "SIN"
    arb_name: str = DEFAULT_ARB
    waveform: NDArray[np.float64] = field(default_factory=_exp_rise)
    sample_rate_Hz: float = 40.0e3
    #: ``FUNC:ARB:FILT``: NORMal (the default), STEP or OFF
    arb_filter: str = "NORM"
    amplitude_Vpp: float = 0.1
    offset_V: float = 0.0
    load_ohm: float = 50.0
    output_on: bool = False
    amplitude_unit: str = "VPP"
    limit_high_V: float = 5.0
    limit_low_V: float = -5.0
    limit_on: bool = False
    burst_mode: str = "TRIG"
    burst_cycles: int = 1
    burst_on: bool = False
    #: ``BURS:INT:PER`` (s), used with an immediate trigger; 10 ms after a reset
    burst_period_s: float = 10.0e-3
    trigger_source: str = "IMM"

    @property
    def peak_V(self) -> float:
        return 0.5 * self.amplitude_Vpp + abs(self.offset_V)


class KeysightEmulator:
    """SCPI emulator; ``handle(message)`` returns the reply of a query, else None."""

    def __init__(
        self, n_channels: int = 2, strict: bool = False, volt_digits: int = 4, srat_digits: int = 9
    ) -> None:
        self.strict = strict
        self.volt_digits = volt_digits
        self.srat_digits = srat_digits
        self.responsive = True
        self.channels: dict[int, ChannelState] = {
            n: ChannelState() for n in range(1, n_channels + 1)
        }
        self.volatile: dict[int, dict[str, NDArray[np.float64]]] = {n: {} for n in self.channels}
        self.byte_order = "NORM"
        self.errors: deque[tuple[int, str]] = deque()
        self.trigger_out_source = 1
        self.trigger_out_on = False
        self.trigger_out_slope = "POS"
        self.trigger_hooks: list[Callable[[tuple[int, ...]], None]] = []
        self.n_triggers = 0
        self.commands: list[str] = []
        self.late_replies = 0
        #: fault injection: each ``DATA:ARB:DAC`` upload keeps only its first n points (None: all)
        self.stored_points: int | None = None
        self._held: list[str] = []

    # --- hooks for the world ------------------------------------------------------------
    def push_error(self, code: int, message: str) -> None:
        """Queue an SCPI error (fault injection); -350 on overflow like the instrument."""
        if len(self.errors) >= QUEUE_LEN:
            self.errors[-1] = (-350, "Queue overflow")
        else:
            self.errors.append((code, message))

    def armed_channels(self) -> tuple[int, ...]:
        """Channels that fire on a bus trigger (burst on, trigger source BUS)."""
        return tuple(
            n for n, c in self.channels.items() if c.burst_on and c.trigger_source == "BUS"
        )

    def clear(self) -> None:
        """Device clear: drop the output queue (late replies too)."""
        self._held.clear()

    # --- wire ---------------------------------------------------------------------------
    def handle(self, message: bytes) -> str | None:
        """One message in; the reply line(s) out (a late reply first, on its own line)."""
        reply = self._handle(message)
        if reply is None:
            return None
        if self.late_replies > 0:
            self.late_replies -= 1
            self._held.append(reply)
            return None
        lines, self._held = [*self._held, reply], []
        return "\n".join(lines)

    def _handle(self, message: bytes) -> str | None:
        block: bytes | None = None
        i = message.find(b"#")
        if i >= 0 and b"DATA" in message[:i].upper():
            try:
                block, rest = _arbitrary_block(message[i:])
            except ValueError:
                self.push_error(-161, "Invalid block data")
                return None
            if rest.strip():
                self.push_error(-161, "Invalid block data")
                return None
            text = message[:i].decode("ascii", "replace")
        else:
            text = message.decode("ascii", "replace")
        self.commands.append(text.strip())
        replies = []
        for part in text.split(";") if block is None else [text]:
            part = part.strip()
            if not part:
                continue
            try:
                reply = self._command(part, block)
            except ScpiError as exc:
                self.push_error(exc.code, exc.message)
                reply = None
            if reply is not None:
                replies.append(reply)
        return ";".join(replies) if replies else None

    def _command(self, text: str, block: bytes | None) -> str | None:
        header, _, arg = text.partition(" ")
        arg = arg.strip()
        query = header.endswith("?")
        header = header.rstrip("?")
        if header.startswith("*"):
            return self._common(header.upper(), query)
        nodes = [n for n in header.lstrip(":").split(":") if n]
        if not nodes:
            raise ScpiError(-113, "Undefined header")
        channel = 1
        short: list[str] = []
        for k, node in enumerate(nodes):
            m = re.fullmatch(r"([A-Za-z]+)(\d*)", node)
            if m is None:
                raise ScpiError(-113, "Undefined header")
            if m.group(2):
                if k > 0 or scpi_short(m.group(1)) not in ("SOUR", "OUTP", "TRIG"):
                    raise ScpiError(-113, "Undefined header")
                channel = int(m.group(2))
            short.append(scpi_short(m.group(1)))
        if channel not in self.channels:
            raise ScpiError(-114, "Header suffix out of range")
        if short[0] == "SOUR":
            short = short[1:]
        key = ":".join(short)
        ch = self.channels[channel]
        return self._dispatch(key, arg, query, channel, ch, block)

    def _common(self, header: str, query: bool) -> str | None:
        if header == "*IDN" and query:
            return IDN
        if header == "*OPC" and query:
            return "1"
        if header == "*TRG":
            fired = self.armed_channels()
            self.n_triggers += 1
            for hook in list(self.trigger_hooks):
                hook(fired)
            return None
        if header == "*RST":
            self.__init__(  # type: ignore[misc]
                len(self.channels), self.strict, self.volt_digits, self.srat_digits
            )
            return None
        if header == "*CLS":
            self.errors.clear()
            return None
        raise ScpiError(-113, "Undefined header")

    def _dispatch(
        self, key: str, arg: str, query: bool, n: int, ch: ChannelState, block: bytes | None
    ) -> str | None:
        if key == "SYST:ERR" and query:
            if not self.errors:
                return '+0,"No error"'
            code, msg = self.errors.popleft()
            return f'{code:+d},"{msg}"'
        if key == "FORM:BORD":
            if query:
                return self.byte_order
            v = arg.upper()
            if v not in ("NORM", "NORMAL", "SWAP", "SWAPPED"):
                raise ScpiError(-224, "Illegal parameter value")
            self.byte_order = v[:4]
            return None
        if key == "DATA:VOL:CLE":
            self.volatile[n].clear()
            ch.arb_name, ch.waveform = DEFAULT_ARB, _exp_rise()  # the old burst is gone
            return None
        if key == "DATA:ARB:DAC":
            self._arb_dac(n, arg, block)
            return None
        if key == "DATA:ATTR:POIN" and query:
            name = arg.strip().strip('"').upper()
            if not name:
                return f"{ch.waveform.size:+d}"
            if name not in self.volatile[n]:
                raise ScpiError(-224, "Illegal parameter value;waveform not in volatile memory")
            return f"{self.volatile[n][name].size:+d}"
        if key == "FUNC":
            if query:
                return ch.function
            v = scpi_short(arg)
            if v not in ("SIN", "SQU", "RAMP", "PULS", "NOIS", "DC", "ARB", "PRBS", "TRI"):
                raise ScpiError(-224, "Illegal parameter value")
            ch.function = v
            return None
        if key == "FUNC:ARB":
            if query:
                return f'"{ch.arb_name}"'
            name = arg.strip('"').upper()
            if name not in self.volatile[n]:
                raise ScpiError(-224, "Illegal parameter value;waveform not in volatile memory")
            ch.arb_name = name
            ch.waveform = self.volatile[n][name]
            return None
        if key == "FUNC:ARB:FILT":
            if query:
                return ch.arb_filter
            v = scpi_short(arg)
            if v not in ("NORM", "STEP", "OFF"):
                raise ScpiError(-224, "Illegal parameter value")
            ch.arb_filter = v
            return None
        if key == "FUNC:ARB:SRAT":
            if query:
                return _nr3(ch.sample_rate_Hz)
            x = self._number(arg)
            if not 1e-6 <= x <= MAX_SRATE:
                raise ScpiError(-222, "Data out of range")
            ch.sample_rate_Hz = _digits(x, self.srat_digits) if self.strict else x
            return None
        if key == "OUTP":
            if query:
                return "1" if ch.output_on else "0"
            ch.output_on = self._bool(arg)
            return None
        if key == "OUTP:LOAD":
            if query:
                return "+9.9E+37" if math.isinf(ch.load_ohm) else _nr3(ch.load_ohm)
            v = arg.upper()
            load = math.inf if v in ("INF", "INFINITY") else self._number(arg)
            if not (math.isinf(load) or 1 <= load <= 10e3):
                raise ScpiError(-222, "Data out of range")
            if ch.limit_on:
                raise ScpiError(-221, "Settings conflict")
            k = _divider(load) / _divider(ch.load_ohm)
            ch.amplitude_Vpp, ch.offset_V, ch.load_ohm = ch.amplitude_Vpp * k, ch.offset_V * k, load
            if math.isinf(load):
                ch.amplitude_unit = "VPP"
            return None
        if key == "VOLT:UNIT":
            if query:
                return ch.amplitude_unit
            v = arg.strip().upper()
            if v not in ("VPP", "VRMS", "DBM"):
                raise ScpiError(-224, "Illegal parameter value")
            if v == "DBM" and math.isinf(ch.load_ohm):
                raise ScpiError(-221, "Settings conflict")
            ch.amplitude_unit = v
            return None
        if key in ("VOLT", "VOLT:OFFS"):
            if query:
                return _nr3(ch.amplitude_Vpp if key == "VOLT" else ch.offset_V)
            self._volt(ch, key, self._number(arg))
            return None
        if key in ("VOLT:LIM:HIGH", "VOLT:LIM:LOW"):
            if query:
                return _nr3(ch.limit_high_V if key.endswith("HIGH") else ch.limit_low_V)
            x = self._number(arg)
            if abs(x) > MAX_HIGHZ_VPP / 2:
                raise ScpiError(-222, "Data out of range")
            if key.endswith("HIGH"):
                ch.limit_high_V = x
            else:
                ch.limit_low_V = x
            return None
        if key == "VOLT:LIM:STAT":
            if query:
                return "1" if ch.limit_on else "0"
            ch.limit_on = self._bool(arg)
            return None
        if key == "BURS:MODE":
            if query:
                return ch.burst_mode
            v = scpi_short(arg)
            if v not in ("TRIG", "GAT"):
                raise ScpiError(-224, "Illegal parameter value")
            ch.burst_mode = v
            return None
        if key == "BURS:NCYC":
            if query:
                return _nr3(ch.burst_cycles)
            x = self._number(arg)
            if x != int(x) or not 1 <= x <= 1e8:
                raise ScpiError(-222, "Data out of range")
            ch.burst_cycles = int(x)
            return None
        if key == "BURS:STAT":
            if query:
                return "1" if ch.burst_on else "0"
            ch.burst_on = self._bool(arg)
            self._fit_burst_period(ch)
            return None
        if key == "BURS:INT:PER":
            if query:
                return _nr3(ch.burst_period_s)
            x = self._number(arg)
            if not 1e-6 <= x <= 8000.0:
                raise ScpiError(-222, "Data out of range")
            ch.burst_period_s = x
            self._fit_burst_period(ch)
            return None
        if key == "TRIG:SOUR":
            if query:
                return ch.trigger_source
            v = scpi_short(arg)
            v = {"EXTE": "EXT", "IMME": "IMM"}.get(v, v)
            if v not in ("BUS", "EXT", "IMM", "TIM"):
                raise ScpiError(-224, "Illegal parameter value")
            ch.trigger_source = v
            self._fit_burst_period(ch)
            return None
        if key == "OUTP:TRIG:SOUR":
            m = re.fullmatch(r"CH(\d)", arg.upper())
            if query:
                return f"CH{self.trigger_out_source}"
            if m is None or int(m.group(1)) not in self.channels:
                raise ScpiError(-224, "Illegal parameter value")
            self.trigger_out_source = int(m.group(1))
            return None
        if key == "OUTP:TRIG:SLOP":
            if query:
                return self.trigger_out_slope
            if scpi_short(arg) not in ("POS", "NEG"):
                raise ScpiError(-224, "Illegal parameter value")
            self.trigger_out_slope = scpi_short(arg)
            return None
        if key == "OUTP:TRIG":
            if query:
                return "1" if self.trigger_out_on else "0"
            self.trigger_out_on = self._bool(arg)
            return None
        raise ScpiError(-113, "Undefined header")

    def _fit_burst_period(self, ch: ChannelState) -> None:
        """The guide's "BURSt Subsystem": with an immediate trigger, a burst period too short for
        the burst's cycles is increased to fit them, and "Settings conflict" is reported."""
        if not (ch.burst_on and ch.trigger_source == "IMM" and ch.function == "ARB"):
            return
        burst_s = ch.burst_cycles * ch.waveform.size / ch.sample_rate_Hz
        if burst_s > ch.burst_period_s:
            ch.burst_period_s = burst_s
            self.push_error(-221, "Settings conflict;burst period increased to fit entire burst")

    def _volt(self, ch: ChannelState, key: str, x: float) -> None:
        """``VOLT`` (Vpp) or ``VOLT:OFFS`` (V) at the present load: refused out of range (-222,
        value kept), or with ``strict`` clipped into range (-222 queued) and rounded."""
        amp = x if key == "VOLT" else ch.amplitude_Vpp
        off = x if key == "VOLT:OFFS" else ch.offset_V
        k = _divider(ch.load_ohm)
        vmax, vmin = MAX_HIGHZ_VPP * k, MIN_HIGHZ_VPP * k
        inside = vmin - 1e-12 <= amp and amp + 2 * abs(off) <= vmax + 1e-9
        if not inside and not self.strict:
            raise ScpiError(-222, "Data out of range")
        if not inside:
            if key == "VOLT":
                amp = min(max(amp, vmin), vmax - 2 * abs(off))
            else:
                off = math.copysign(min(abs(off), (vmax - amp) / 2), off)
            self.push_error(-222, "Data out of range")
        if self.strict:
            amp, off = _digits(amp, self.volt_digits), _digits(off, self.volt_digits)
        if ch.limit_on and (
            off + amp / 2 > ch.limit_high_V + 1e-9 or off - amp / 2 < ch.limit_low_V - 1e-9
        ):
            # the guide's "Voltage limits": the setting is clipped to what the limits allow and
            # "Settings conflict" reported (before: refused, the old value kept)
            lo, hi = ch.limit_low_V, ch.limit_high_V
            if key == "VOLT:OFFS" and amp <= hi - lo:
                off = min(max(off, lo + amp / 2), hi - amp / 2)
            else:  # the amplitude gives way (also for an offset its amplitude cannot fit)
                off = min(max(off, lo), hi)
                amp = max(0.0, 2 * min(hi - off, off - lo))
            self.push_error(-221, "Settings conflict;amplitude exceeds voltage limits")
        ch.amplitude_Vpp, ch.offset_V = amp, off

    def _arb_dac(self, n: int, arg: str, block: bytes | None) -> None:
        name = arg.rstrip(",").strip().strip('"').upper()
        if not re.fullmatch(r"[A-Z][A-Z0-9_]{0,11}", name):
            raise ScpiError(-224, "Illegal parameter value;bad arb name")
        if block is None:
            raise ScpiError(-109, "Missing parameter")
        if len(block) % 2 or len(block) < 16:
            raise ScpiError(-161, "Invalid block data")
        dtype = "<i2" if self.byte_order == "SWAP" else ">i2"
        codes = np.frombuffer(block, dtype=dtype).astype(np.float64)
        if np.any(np.abs(codes) > 32767):
            raise ScpiError(-222, "Data out of range")
        self.volatile[n][name] = codes[: self.stored_points] / 32767.0

    @staticmethod
    def _number(arg: str) -> float:
        a = arg.strip().upper()
        if a in ("MIN", "MAX", "DEF"):
            raise ScpiError(-224, "Illegal parameter value")
        if not a:
            raise ScpiError(-109, "Missing parameter")
        if not _NUM.match(a):
            raise ScpiError(-104, "Data type error")
        return float(a)

    @staticmethod
    def _bool(arg: str) -> bool:
        a = arg.strip().upper()
        if a in ("ON", "1"):
            return True
        if a in ("OFF", "0"):
            return False
        raise ScpiError(-224, "Illegal parameter value")
