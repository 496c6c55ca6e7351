"""Keysight 33500B / 33600A two-channel waveform generator (SCPI), playing one burst per trigger.

Configuration, as the programming guide orders it (per channel ``n``)::

    OUTPn OFF                                  output stays off until armed
    SOURn:DATA:VOL:CLE                          clear volatile arb memory
    FORM:BORD SWAP                              binary blocks little-endian (set explicitly)
    SOURn:DATA:ARB:DAC BIAFCn,#<n><len><int16...>   the burst as DAC codes -32767..32767
    SOURn:DATA:ATTR:POIN? BIAFCn                 the points stored: all of them, or refused
    SOURn:FUNC ARB ; SOURn:FUNC:ARB BIAFCn
    SOURn:FUNC:ARB:FILT NORM                    the flat-band filter between points (default)
    SOURn:FUNC:ARB:SRAT <Sa/s>
    SOURn:VOLT:LIM:STAT OFF                     the load cannot change while limits are on
    OUTPn:LOAD INF ; SOURn:VOLT:UNIT VPP         high impedance (piezo amplifier input), Vpp
    SOURn:VOLT:LIM:HIGH/LOW, SOURn:VOLT:LIM:STAT ON  hard output limits (bench safety)
    SOURn:VOLT <Vpp> ; SOURn:VOLT:OFFS <V>
    SOURn:BURS:MODE TRIG ; SOURn:BURS:NCYC 1 ; SOURn:BURS:STAT ON
    TRIGn:SOUR BUS|EXT|IMM
    OUTP:TRIG:SOUR CHn ; OUTP:TRIG:SLOP POS ; OUTP:TRIG ON   trigger out to the digitiser
    every setting above queried back             (instruments.keysight_readback)
    SYST:ERR? until +0                          a mismatch or an error: outputs off, ReplyError

What the channel reports holding after this (not what was asked) is what :meth:`snapshot`
records: a coerced value (an amplitude clipped, a rate quantised, a load change refused) is an
error naming the setting, the request and the read-back value, never a silent record.

The instrument plays an arbitrary waveform of ``n`` points in ``n / SRAT`` seconds (point ``k``
at ``k / SRAT``): a burst sampled over its window ``T`` with ``n`` points (first and last at 0
and ``T``) is played at ``SRAT = (n - 1) / T``, read back, so the carrier is the protocol's.

At connect, ``*CLS`` clears the error queue (a stale error is not blamed on the first command)
and ``*IDN?`` names the instrument. After a query times out, the link is brought back in step
before anything else: device clear (the instrument drops its late reply), then ``*OPC?`` must
read ``1``; otherwise the link is reported out of step.
"""

from __future__ import annotations

import logging
import math
import re
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from instruments.burst import burst_samples
from instruments.errors import InstrumentError, InstrumentTimeout, LimitError, ReplyError
from instruments.interfaces import BurstConfig, Transport
from instruments.keysight_readback import (
    ChannelReadback,
    ChannelRequest,
    parse_count,
    read_channel,
)

__all__ = [
    "DAC_FULL_SCALE",
    "GeneratorLimits",
    "KeysightGenerator",
    "arb_peak_factor",
    "dac_codes",
    "supported_model",
    "unequal_peaks",
]

log = logging.getLogger(__name__)

#: DAC code of a normalised sample of +1 (the 33500B/33600A arb range is -32767..+32767)
DAC_FULL_SCALE = 32767
_TRIGGER_SOURCE = {"bus": "BUS", "external": "EXT", "immediate": "IMM"}
_ERROR_RE = re.compile(r'^\s*([+-]?\d+)\s*,\s*"(.*)"\s*$')
_MAX_ERRORS = 64


@dataclass(frozen=True)
class GeneratorLimits:
    """Safety and device limits, from the bench file (refused before anything is sent).

    Attributes
    ----------
    max_piezo_V:
        Largest |voltage| allowed at the piezo terminals (V).
    amplifier_gain:
        Power amplifier voltage gain (V/V): piezo V = generator V x gain.
    max_amplitude_Vpp:
        Generator's own maximum amplitude at the load setting (Vpp; 20 Vpp into high Z for
        the 33500B, or the bench's lower cap).
    max_sample_rate_Hz:
        Arbitrary-waveform sample-rate ceiling (Sa/s).
    max_points:
        Largest arbitrary waveform (samples).
    min_amplitude_Vpp:
        Smallest amplitude the generator plays (Vpp): 1 mVpp into 50 ohm, 2 mVpp at the high
        impedance this driver sets (33500B/33600A data sheets); below it the instrument clips
        and queues -222.
    """

    max_piezo_V: float
    amplifier_gain: float
    max_amplitude_Vpp: float = 20.0
    max_sample_rate_Hz: float = 160.0e6
    max_points: int = 1_000_000
    min_amplitude_Vpp: float = 2.0e-3

    def __post_init__(self) -> None:
        for name in ("max_piezo_V", "amplifier_gain", "max_amplitude_Vpp", "max_sample_rate_Hz",
                     "min_amplitude_Vpp"):  # fmt: skip
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise LimitError(f"generator limits: {name} must be > 0, got {value!r}")
        if self.max_points < 8:
            raise LimitError(f"generator limits: max_points must be >= 8, got {self.max_points}")

    @property
    def max_generator_peak_V(self) -> float:
        """Largest |V| at the generator terminals allowed by both limits."""
        return min(0.5 * self.max_amplitude_Vpp, self.max_piezo_V / self.amplifier_gain)

    def check(self, config: BurstConfig, peak_factor: float = 1.0) -> None:
        """Raise :class:`LimitError` (numbers in the message) if ``config`` breaks a limit;
        ``peak_factor``: the waveform's :func:`arb_peak_factor` (the piezo's peak is taken as
        ``amplitude_Vpp / 2 x peak_factor + |offset|`` at the generator)."""
        if config.amplitude_Vpp < self.min_amplitude_Vpp:
            raise LimitError(
                f"generator amplitude {config.amplitude_Vpp:g} Vpp is below the generator "
                f"minimum {self.min_amplitude_Vpp:g} Vpp at high-Z load"
            )
        if config.amplitude_Vpp + 2 * abs(config.offset_V) > self.max_amplitude_Vpp:
            raise LimitError(
                f"generator amplitude {config.amplitude_Vpp:g} Vpp with offset "
                f"{config.offset_V:g} V exceeds the generator maximum "
                f"{self.max_amplitude_Vpp:g} Vpp at high-Z load"
            )
        peak_V = 0.5 * config.amplitude_Vpp * peak_factor + abs(config.offset_V)
        piezo_V = peak_V * self.amplifier_gain
        if piezo_V > self.max_piezo_V * (1 + 1e-12):
            why = unequal_peaks(peak_factor, "waveform")
            raise LimitError(
                f"peak at the piezo {piezo_V:g} V (generator peak {peak_V:g} V x gain "
                f"{self.amplifier_gain:g}) exceeds the piezo limit {self.max_piezo_V:g} V"
                + (f"; {why}" if why else "")
            )
        if config.sample_rate_Hz > self.max_sample_rate_Hz:
            raise LimitError(
                f"arb sample rate {config.sample_rate_Hz:g} Sa/s exceeds the generator maximum "
                f"{self.max_sample_rate_Hz:g} Sa/s"
            )


def arb_peak_factor(samples: NDArray[np.float64]) -> float:
    """The largest |output| of arbitrary data ``samples`` ``[n]`` (in [-1, 1]) in units of half
    the amplitude setting (VOLT/2), under either reading of how the 33500/33600 scales VOLT on
    arb data; no Keysight text found settles which (docs/instruments.md): the DAC's full
    scale at +-VOLT/2 (factor ``max|x|``, at most 1), or the data's own peak-to-peak at VOLT
    (factor ``2 max|x| / (max x - min x)``: 1 for data whose peaks are equal, 1.005 for the
    shipped narrowband bursts, 1.09 for a five-cycle one). The piezo limit is checked with the
    larger; 1 for data of fewer than two distinct values."""
    x = np.asarray(samples, dtype=np.float64)
    if x.size == 0 or not np.all(np.isfinite(x)):
        return 1.0
    top, bottom = float(np.max(x)), float(np.min(x))
    if top <= bottom:
        return 1.0
    peak = max(abs(top), abs(bottom))
    return max(peak, 2.0 * peak / (top - bottom))


def unequal_peaks(peak_factor: float, what: str = "burst") -> str:
    """``"the burst's peaks are unequal, so it may reach x1.088 of half its Vpp"``: why a piezo
    limit was checked at more than half the Vpp (``peak_factor``: :func:`arb_peak_factor`),
    or "" where it was not."""
    if not peak_factor > 1.0 + 1e-9:
        return ""
    return f"the {what}'s peaks are unequal, so it may reach x{peak_factor:.4g} of half its Vpp"


def dac_codes(samples: NDArray[np.float64]) -> NDArray[np.int16]:
    """Normalised samples ``[n]`` in [-1, 1] -> int16 DAC codes ``[n]`` (+1 -> 32767).

    Raises :class:`LimitError` on NaN/inf or |sample| > 1.
    """
    x = np.asarray(samples, dtype=np.float64)
    if x.ndim != 1:
        raise LimitError(f"waveform must be 1-D, got shape {x.shape}")
    if not np.all(np.isfinite(x)):
        bad = int(np.flatnonzero(~np.isfinite(x))[0])
        raise LimitError(f"waveform sample {bad} is not finite ({x[bad]!r})")
    peak = float(np.max(np.abs(x))) if x.size else 0.0
    if peak > 1.0 + 1e-12:
        raise LimitError(f"waveform must be normalised to |x| <= 1, peak is {peak:g}")
    return np.rint(np.clip(x, -1.0, 1.0) * DAC_FULL_SCALE).astype(np.int16)


def supported_model(model: str) -> bool:
    """Whether ``model`` (the second field of ``*IDN?``, e.g. ``"33522B"``) is one this driver
    speaks to: the 33500B and 33600A series."""
    return model.strip().upper().startswith(("335", "336"))


class KeysightGenerator:
    """Keysight 33500B / 33600A on a :class:`Transport` (implements ``FunctionGenerator``).

    Parameters
    ----------
    transport:
        An open transport (VISA in the lab, :class:`SimTransport` in the simulated bench).
    limits:
        Safety limits; every burst is checked against them before a byte is sent.
    channels:
        Channel numbers available (1-based).
    """

    def __init__(
        self, transport: Transport, limits: GeneratorLimits, channels: tuple[int, ...] = (1, 2)
    ) -> None:
        self.transport = transport
        self.limits = limits
        self.channels = tuple(channels)
        self._configs: dict[int, BurstConfig] = {}
        self._readback: dict[int, ChannelReadback] = {}
        self._idn: str | None = None
        #: what SYST:ERR? held when the bench connected, before its *CLS (``biafc check``)
        self.errors_at_connect: list[str] = []

    # --- link -------------------------------------------------------------------------------
    def _query(self, command: str) -> str:
        """Query; after a timeout the link is resynchronised (:meth:`resync`) before raising."""
        try:
            return self.transport.query(command)
        except InstrumentTimeout:
            self.resync(command)
            raise

    def resync(self, after: str = "a timeout") -> None:
        """Device clear and drain, then ``*OPC?`` must answer ``1``: a late reply is never read
        as the answer to the next query. :class:`InstrumentError` when the link stays out of
        step or silent."""
        name = self.transport.name
        clear = getattr(self.transport, "clear", None)
        if clear is not None:
            try:
                clear()
            except InstrumentError as exc:
                log.warning("%s: device clear failed: %s", name, exc)
        try:
            reply = self.transport.query("*OPC?")
        except InstrumentTimeout:
            raise InstrumentTimeout(
                f"{name}: no reply to {after!r} within {self.transport.timeout_s:g} s, nor to "
                "'*OPC?' after a device clear: check that the generator is on and connected"
            ) from None
        if reply.strip() not in ("1", "+1"):
            raise InstrumentError(
                f"{name}: link out of step after a timeout on {after!r} (*OPC? read {reply!r})"
            )

    def connect(self) -> str:
        """Device clear (a reply that an earlier session left unread is dropped: ``*CLS``
        clears the error queue, not the output queue; skipped where the VISA session has none,
        as pyvisa-py's USB and serial sessions), ``*IDN?``, the errors left in the queue kept
        as :attr:`errors_at_connect` (logged; ``biafc check`` shows them), ``*CLS``; returns
        the identity. An instrument that is not a 33500/33600 is refused
        (:class:`InstrumentError`): a run configured and switched on whatever answered."""
        clear = getattr(self.transport, "clear", None)
        if clear is not None:
            try:
                clear()
            except InstrumentTimeout:  # a dead link: said now, not after *IDN? times out too
                raise
            except InstrumentError as exc:  # pyvisa-py has no device clear on USB or ASRL
                log.info("%s: no device clear at connect (%s)", self.transport.name, exc)
        idn = self.identify()  # first: a wrong instrument is named as such, not by a bad reply
        fields = [p.strip() for p in idn.split(",")]
        if not supported_model(fields[1]):
            raise InstrumentError(
                f"{self.transport.name} answers as {fields[0]} {fields[1]}, not a Keysight "
                "33500B/33600A: check generator.resource"
            )
        self.errors_at_connect = self.errors()
        if self.errors_at_connect:
            log.info("%s: errors left from before, cleared: %s", self.transport.name,
                     "; ".join(self.errors_at_connect))  # fmt: skip
        self.transport.write("*CLS")
        return idn

    def identity(self) -> dict[str, Any]:
        """Identity and, per channel, the output load as the instrument reports it (ohm;
        ``inf`` for high Z), for ``biafc check``."""
        idn = self._idn or self.identify()
        loads: dict[str, float] = {}
        for ch in self.channels:
            raw = self._query(f"OUTP{ch}:LOAD?")
            try:
                value = float(raw)
            except ValueError:
                raise ReplyError(f"{self.transport.name}: OUTP{ch}:LOAD? read {raw!r}") from None
            loads[str(ch)] = math.inf if value >= 9.9e37 else value
        return {"identity": idn, "load_ohm": loads}

    # --- identity and errors ----------------------------------------------------------------
    def identify(self) -> str:
        """``*IDN?`` -> ``"Keysight Technologies,33522B,MY...,x.y"`` (ReplyError if malformed)."""
        reply = self._query("*IDN?")
        if reply.count(",") != 3:
            raise ReplyError(f"{self.transport.name}: malformed *IDN? reply {reply!r}")
        self._idn = reply
        return reply

    def errors(self) -> list[str]:
        """Drain ``SYST:ERR?`` until ``+0``; returns e.g. ``["-222,Data out of range"]``."""
        found: list[str] = []
        for _ in range(_MAX_ERRORS):
            reply = self._query("SYST:ERR?")
            m = _ERROR_RE.match(reply)
            if m is None:
                raise ReplyError(f"{self.transport.name}: malformed SYST:ERR? reply {reply!r}")
            if int(m.group(1)) == 0:
                return found
            found.append(f"{int(m.group(1))},{m.group(2)}")
        raise ReplyError(f"{self.transport.name}: error queue does not drain: {found[-3:]}")

    def check_errors(self, context: str) -> None:
        """Raise :class:`ReplyError` listing the queued errors after ``context``."""
        errs = self.errors()
        if errs:
            raise ReplyError(f"{self.transport.name}: {context}: " + "; ".join(errs))

    # --- configuration ----------------------------------------------------------------------
    def _check_channel(self, channel: int) -> None:
        if channel not in self.channels:
            raise LimitError(f"generator channel {channel!r} not in {self.channels}")

    def configure_burst(self, channel: int, config: BurstConfig) -> None:
        """Upload and arm ``config`` on ``channel`` (1-based); the output stays off.

        Limits and waveform are checked before anything is sent; any failure while
        configuring leaves the generator in its safe state (outputs off).
        """
        self._check_channel(channel)
        self.limits.check(config)
        samples = burst_samples(config.shape, config.sample_rate_Hz)
        # n points over the window T: the instrument plays point k at k / SRAT
        played_rate = (samples.size - 1) / config.shape.duration_s
        self.configure_waveform(channel, samples, config, played_rate)

    def configure_waveform(
        self,
        channel: int,
        samples: NDArray[np.float64],
        config: BurstConfig,
        sample_rate_Hz: float | None = None,
    ) -> None:
        """As :meth:`configure_burst` with explicit normalised ``samples`` ``[n]`` (|x| <= 1)
        played at ``sample_rate_Hz`` (Sa/s; default ``config.sample_rate_Hz``): point ``k`` at
        ``k / sample_rate_Hz`` s. Every setting is read back and compared
        (:mod:`instruments.keysight_readback`: the rate to 1e-6, voltages to 0.1 % + 0.1 mV)."""
        self._check_channel(channel)
        if config.trigger_source == "external":
            raise LimitError(
                f"{self.transport.name}: trigger source 'external' turns off the trigger out that "
                "starts the digitiser (the guide: 'With TRIGger[1|2]:SOURce EXTernal, instrument "
                "disables the \"trigger out\" signal'); use 'bus' or 'immediate'"
            )
        codes = dac_codes(samples)  # finite and normalised, before the limits read them
        self.limits.check(config, peak_factor=arb_peak_factor(samples))
        rate = float(config.sample_rate_Hz if sample_rate_Hz is None else sample_rate_Hz)
        if not (math.isfinite(rate) and 0 < rate <= self.limits.max_sample_rate_Hz):
            raise LimitError(
                f"arb sample rate {rate:g} Sa/s outside (0, {self.limits.max_sample_rate_Hz:g}]"
            )
        if not 8 <= codes.size <= self.limits.max_points:
            raise LimitError(
                f"waveform has {codes.size} samples; the generator takes "
                f"8..{self.limits.max_points}"
            )
        data = codes.astype("<i2").tobytes()
        self._configs.pop(channel, None)
        self._readback.pop(channel, None)
        n = channel
        peak = self.limits.max_generator_peak_V
        request = ChannelRequest(
            arb_name=f"BIAFC{n}",
            sample_rate_Hz=rate,
            amplitude_Vpp=config.amplitude_Vpp,
            offset_V=config.offset_V,
            limit_high_V=peak,
            limit_low_V=-peak,
            trigger_source=_TRIGGER_SOURCE[config.trigger_source],
        )
        try:
            self._write_config(n, data, request)
            held = self._check_held(n, request)
        except InstrumentError:
            self.safe_state()
            raise
        self._readback[channel] = held
        self._configs[channel] = config

    def held(self, channel: int) -> ChannelReadback | None:
        """What ``channel`` reported holding after its last configuration (None before)."""
        return self._readback.get(channel)

    def _check_held(self, n: int, request: ChannelRequest) -> ChannelReadback:
        """Read channel ``n`` back, then drain the error queue; :class:`ReplyError` naming every
        mismatch (setting, requested and read-back value, tolerance) and every queued error."""
        name = self.transport.name
        held, mismatches = read_channel(self._query, name, n, request)
        errs = self.errors()
        if mismatches:
            also = f"; instrument errors: {'; '.join(errs)}" if errs else ""
            raise ReplyError(f"{name}: {'; '.join(mismatches)}{also}")
        if errs:
            raise ReplyError(f"{name}: configuring channel {n}: " + "; ".join(errs))
        return held

    def _check_points(self, n: int, name: str, sent: int) -> None:
        """``SOURn:DATA:ATTRibute:POINts? <name>``, "the number of points in the specified
        arbitrary waveform segment" (33500B programming reference), must be the ``sent`` points:
        a truncated upload is a :class:`ReplyError` before the arb is selected or armed."""
        query = f"SOUR{n}:DATA:ATTR:POIN? {name}"
        raw = self._query(query)
        try:
            stored = parse_count(raw)
        except ValueError:
            raise ReplyError(
                f"{self.transport.name}: channel {n}: unreadable {query} reply {raw!r}"
            ) from None
        if stored != sent:
            raise ReplyError(
                f"{self.transport.name}: channel {n} arb waveform {name}: sent {sent} points, "
                f"stored {stored}"
            )

    def _write_config(self, n: int, data: bytes, req: ChannelRequest) -> None:
        """The configuration of channel ``n`` as the programming guide orders it; the voltage
        limits go off before the load setting (the instrument refuses a load change while they
        are on) and on again before amplitude and offset."""
        w = self.transport.write
        w(f"OUTP{n} OFF")
        w(f"SOUR{n}:DATA:VOL:CLE")
        w(f"FORM:BORD {req.byte_order}")
        self.transport.write_block(f"SOUR{n}:DATA:ARB:DAC {req.arb_name},", data)
        self._check_points(n, req.arb_name, len(data) // 2)
        w(f"SOUR{n}:FUNC {req.function}")
        w(f"SOUR{n}:FUNC:ARB {req.arb_name}")
        # the filter first: left OFF, it caps the rate at 62.5 MSa/s (33500) and would clip SRAT
        w(f"SOUR{n}:FUNC:ARB:FILT {req.arb_filter}")
        w(f"SOUR{n}:FUNC:ARB:SRAT {req.sample_rate_Hz:.12g}")
        w(f"SOUR{n}:VOLT:LIM:STAT OFF")
        w(f"OUTP{n}:LOAD {req.load}")
        w(f"SOUR{n}:VOLT:UNIT {req.amplitude_unit}")
        w(f"SOUR{n}:VOLT:LIM:HIGH {req.limit_high_V:.6g}")
        w(f"SOUR{n}:VOLT:LIM:LOW {req.limit_low_V:.6g}")
        w(f"SOUR{n}:VOLT:LIM:STAT ON")
        # offset 0 first: the old amplitude with the new offset could cross a limit (the
        # instrument then clips it and reports a conflict); the limits are symmetric
        w(f"SOUR{n}:VOLT:OFFS 0")
        w(f"SOUR{n}:VOLT {req.amplitude_Vpp:.6g}")
        if req.offset_V != 0:
            w(f"SOUR{n}:VOLT:OFFS {req.offset_V:.6g}")
        w(f"SOUR{n}:BURS:MODE {req.burst_mode}")
        w(f"SOUR{n}:BURS:NCYC {req.burst_cycles}")
        # the trigger source before the burst goes on, as the guide orders it: under the
        # default immediate trigger a burst longer than the 10 ms period is a conflict
        w(f"TRIG{n}:SOUR {req.trigger_source}")
        w(f"SOUR{n}:BURS:STAT ON")
        w(f"OUTP:TRIG:SOUR CH{n}")
        w(f"OUTP:TRIG:SLOP {req.trigger_out_slope}")
        w("OUTP:TRIG ON")

    def output(self, channel: int, on: bool) -> None:
        """Switch ``channel``'s output; switching on needs a configured burst."""
        self._check_channel(channel)
        if on and channel not in self._configs:
            raise InstrumentError(
                f"{self.transport.name}: configure a burst on channel {channel} before output on"
            )
        self.transport.write(f"OUTP{channel} {'ON' if on else 'OFF'}")
        try:
            self.check_errors(f"output {channel} {'on' if on else 'off'}")
        except InstrumentError:
            self.safe_state()
            raise
        if on:  # the trigger out follows the channel being played
            self.transport.write(f"OUTP:TRIG:SOUR CH{channel}")

    def output_state(self, channel: int) -> bool:
        """Read back ``OUTPn?`` (reply ``1`` or ``0``): whether ``channel``'s output is on.

        The confirmation of the safe state: a silent generator raises
        :class:`InstrumentTimeout`, a reply other than 0/1 :class:`ReplyError`.
        """
        self._check_channel(channel)
        reply = self._query(f"OUTP{channel}?").strip().upper()
        if reply in ("1", "+1", "ON"):
            return True
        if reply in ("0", "+0", "OFF"):
            return False
        raise ReplyError(f"{self.transport.name}: unexpected OUTP{channel}? reply {reply!r}")

    def trigger(self) -> None:
        """Bus trigger (``*TRG``): every channel armed with ``TRIG:SOUR BUS`` fires."""
        self.transport.write("*TRG")

    def wait_complete(self, timeout_s: float | None = None) -> None:
        """``*OPC?`` (reply ``1``), optionally with a longer timeout."""
        old = self.transport.timeout_s
        if timeout_s is not None:
            self.transport.timeout_s = timeout_s
        try:
            reply = self._query("*OPC?")
        finally:
            self.transport.timeout_s = old
        if reply.strip() not in ("1", "+1"):
            raise ReplyError(f"{self.transport.name}: unexpected *OPC? reply {reply!r}")

    # --- provenance and safety --------------------------------------------------------------
    def snapshot(self) -> dict[str, Any]:
        """Identity, limits and per channel: the output's state as the instrument reports it
        now (``OUTPn?``; ``None`` with ``output_error`` when it does not answer: before, the
        state last asked for, "off" even after an off that was never confirmed), the burst
        shape asked for, and every setting as the channel reported it after configuration
        (``read_back``, SI units: Vpp, V, Sa/s, ohm or ``"INF"``). JSON-serialisable."""
        chans: dict[str, Any] = {}
        for ch in self.channels:
            cfg = self._configs.get(ch)
            held = self._readback.get(ch)
            entry: dict[str, Any] = {}
            try:
                entry["output_on"] = self.output_state(ch)
            except InstrumentError as exc:
                entry["output_on"] = None
                entry["output_error"] = str(exc).splitlines()[0] if str(exc) else repr(exc)
            if cfg is not None and held is not None:
                entry.update(
                    f_center_Hz=cfg.shape.f_center_Hz,
                    cycles=cfg.shape.cycles,
                    width_s=cfg.shape.width_s,
                    read_back=held.as_json(),
                )
            chans[str(ch)] = entry
        return {
            "model": "Keysight 33500B/33600A",
            "identity": self._idn,
            "resource": self.transport.name,
            "limits": {
                "max_piezo_V": self.limits.max_piezo_V,
                "amplifier_gain": self.limits.amplifier_gain,
                "max_amplitude_Vpp": self.limits.max_amplitude_Vpp,
            },
            "channels": chans,
        }

    def safe_state(self) -> None:
        """All outputs off; never raises (a dead link is logged)."""
        for ch in self.channels:
            try:
                self.transport.write(f"OUTP{ch} OFF")
            except Exception as exc:
                log.warning("%s: could not switch output %d off: %s", self.transport.name, ch, exc)

    def close(self) -> None:
        self.safe_state()
        self.transport.close()
