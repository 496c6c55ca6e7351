"""Zaber linear stage, ASCII protocol, positions in metres.

Request ``/<device> <axis> <command>``; reply ``@<device> <axis> <OK|RJ> <IDLE|BUSY> <flag> <data>``
e.g. ``@01 1 OK IDLE -- 0``. Warning flags (``--`` when none): ``WR`` no reference position
(not homed), ``FS`` stalled and stopped, ``WL`` unexpected limit switch, ``FQ``/``FE`` encoder
faults, ``NI`` a move was interrupted. Positions travel as microsteps; ``microstep_m`` converts.
Speeds travel as ``microsteps/s x 1.6384`` (``maxspeed`` units).
"""

from __future__ import annotations

import logging
import math
import re
from dataclasses import dataclass, field
from typing import Any

from instruments.clock import Clock, SystemClock
from instruments.errors import (
    InstrumentError,
    InstrumentTimeout,
    LimitError,
    NotHomedError,
    ReplyError,
    StallError,
)
from instruments.interfaces import Transport

__all__ = ["SPEED_UNIT", "ZaberReply", "ZaberSettings", "ZaberStage", "parse_reply"]

log = logging.getLogger(__name__)

#: ``maxspeed`` data per (microstep/s)
SPEED_UNIT = 1.6384
_REPLY_RE = re.compile(r"^@(\d+)\s+(\d+)\s+(?:(\d+)\s+)?(OK|RJ)\s+(IDLE|BUSY)\s+(\S\S)\s*(.*)$")
_FAULT_FLAGS = {"FS": "stalled and stopped", "FQ": "encoder error", "FE": "encoder fault"}
_LIMIT_FLAGS = {"WL": "unexpected limit switch"}


@dataclass(frozen=True)
class ZaberReply:
    """One parsed reply line."""

    device: int
    axis: int
    ok: bool
    busy: bool
    flag: str
    data: str


def parse_reply(line: str) -> ZaberReply:
    """Parse ``@01 1 OK IDLE -- 0``; :class:`ReplyError` if malformed."""
    m = _REPLY_RE.match(line.strip())
    if m is None:
        raise ReplyError(f"malformed Zaber reply {line!r}")
    return ZaberReply(
        int(m.group(1)),
        int(m.group(2)),
        m.group(4) == "OK",
        m.group(5) == "BUSY",
        m.group(6),
        m.group(7).strip(),
    )


@dataclass(frozen=True)
class ZaberSettings:
    """Stage settings from the bench file (SI units).

    Attributes
    ----------
    device, axis:
        Zaber device address and axis number.
    microstep_m:
        Length of one microstep (m), from the stage's datasheet.
    soft_limits_m:
        (low, high) m, intersected with the device limits; ``None``: device limits only.
    speed_m_per_s:
        Move speed (m/s), set with ``set maxspeed`` on connect.
    approach_m:
        Same-side approach: every move ends travelling towards +x over at least this
        distance (backlash); 0 disables.
    settle_s:
        Wait after a move before :meth:`ZaberStage.move_to` returns (s).
    poll_interval_s:
        Status polling period while moving (s).
    timeout_margin_s:
        Added to distance / speed to get a move's timeout (s).
    home_timeout_s:
        Homing timeout (s).
    position_tolerance_m:
        Largest |reached - target| accepted after a move (m).
    clock:
        Time source for polling (the simulated bench injects its simulated clock).
    """

    device: int = 1
    axis: int = 1
    microstep_m: float = 0.49609375e-6
    soft_limits_m: tuple[float, float] | None = None
    speed_m_per_s: float = 0.025
    approach_m: float = 0.5e-3
    settle_s: float = 0.2
    poll_interval_s: float = 0.05
    timeout_margin_s: float = 5.0
    home_timeout_s: float = 120.0
    position_tolerance_m: float = 2.0e-6
    clock: Clock = field(default_factory=SystemClock, compare=False)

    def __post_init__(self) -> None:
        for name in ("microstep_m", "speed_m_per_s", "poll_interval_s", "home_timeout_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise LimitError(f"stage {name} must be > 0, got {value!r}")
        for name in ("approach_m", "settle_s", "timeout_margin_s", "position_tolerance_m"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise LimitError(f"stage {name} must be >= 0, got {value!r}")
        if self.soft_limits_m is not None:
            lo, hi = self.soft_limits_m
            if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
                raise LimitError(f"stage soft limits must be low < high, got {self.soft_limits_m}")


class ZaberStage:
    """A Zaber axis on a :class:`Transport` (implements ``Stage``); positions in metres."""

    def __init__(self, transport: Transport, settings: ZaberSettings | None = None) -> None:
        self.transport = transport
        self.settings = settings or ZaberSettings()
        self._device_limits_m: tuple[float, float] | None = None
        self._speed_set = False

    # --- wire ---------------------------------------------------------------------------
    def command(self, text: str) -> ZaberReply:
        """Send ``/<dev> <axis> <text>``, parse the reply; RJ -> error, fault flags -> error."""
        s = self.settings
        cmd = f"/{s.device} {s.axis} {text}".rstrip()
        reply = self.transport.query(cmd)
        for _ in range(8):  # skip info (#) and alert (!) messages between command and reply
            if not reply.startswith(("#", "!")):
                break
            reply = self.transport.read()
        try:
            r = parse_reply(reply)
        except ReplyError:
            raise ReplyError(
                f"{self.transport.name}: malformed reply to {cmd!r}: {reply!r}"
            ) from None
        if r.device != s.device:
            raise ReplyError(f"{self.transport.name}: reply to {cmd!r} from device {r.device}")
        self._check_flags(cmd, r)
        if not r.ok:
            if r.flag == "WR":
                raise NotHomedError(f"{self.transport.name}: {cmd!r} rejected: stage not homed")
            raise ReplyError(f"{self.transport.name}: {cmd!r} rejected ({r.data or r.flag})")
        return r

    def _check_flags(self, cmd: str, r: ZaberReply) -> None:
        if r.flag in _FAULT_FLAGS:
            raise StallError(
                f"{self.transport.name}: {_FAULT_FLAGS[r.flag]} ({r.flag}) after {cmd!r}"
            )
        if r.flag in _LIMIT_FLAGS:
            raise StallError(
                f"{self.transport.name}: {_LIMIT_FLAGS[r.flag]} ({r.flag}) after {cmd!r}"
            )

    def _steps(self, position_m: float) -> int:
        return round(float(position_m) / self.settings.microstep_m)

    def _get_int(self, setting: str) -> int:
        r = self.command(f"get {setting}")
        try:
            return int(r.data.split()[0])
        except (ValueError, IndexError):
            raise ReplyError(
                f"{self.transport.name}: 'get {setting}' answered {r.data!r}"
            ) from None

    # --- Stage interface ----------------------------------------------------------------
    def status(self) -> ZaberReply:
        """The axis status (empty command)."""
        return self.command("")

    def is_homed(self) -> bool:
        r = self.command("")
        return r.flag != "WR"

    def home(self) -> None:
        """Home and block until idle (timeout ``home_timeout_s``)."""
        self.command("home")
        self._wait_idle("home", self.settings.home_timeout_s)
        self._ensure_speed()

    def _ensure_speed(self) -> None:
        if not self._speed_set:
            s = self.settings
            data = round(float(s.speed_m_per_s) / s.microstep_m * SPEED_UNIT)
            self.command(f"set maxspeed {data}")
            self._speed_set = True

    def speed(self) -> float:
        """Current ``maxspeed`` in m/s."""
        return self._get_int("maxspeed") / SPEED_UNIT * self.settings.microstep_m

    def position(self) -> float:
        return self._get_int("pos") * self.settings.microstep_m

    def limits(self) -> tuple[float, float]:
        """(low, high) m: device ``limit.min/max`` intersected with the soft limits."""
        if self._device_limits_m is None:
            step = self.settings.microstep_m
            self._device_limits_m = (
                self._get_int("limit.min") * step,
                self._get_int("limit.max") * step,
            )
        lo, hi = self._device_limits_m
        if self.settings.soft_limits_m is not None:
            lo = max(lo, self.settings.soft_limits_m[0])
            hi = min(hi, self.settings.soft_limits_m[1])
        if lo >= hi:
            raise LimitError(
                f"{self.transport.name}: soft limits {self.settings.soft_limits_m} do not overlap "
                f"the device travel {self._device_limits_m} m"
            )
        return lo, hi

    def move_to(self, position_m: float) -> None:
        """Move to ``position_m`` (m) from below (same-side approach), block until idle, settle.

        Refused (nothing sent) when not finite or outside :meth:`limits`; :class:`NotHomedError`
        when not homed.
        """
        if not math.isfinite(position_m):
            raise LimitError(f"{self.transport.name}: target position {position_m!r} is not finite")
        lo, hi = self.limits()
        if not lo <= position_m <= hi:
            raise LimitError(
                f"{self.transport.name}: target {position_m * 1e3:.4f} mm outside the travel "
                f"[{lo * 1e3:.4f}, {hi * 1e3:.4f}] mm"
            )
        if not self.is_homed():
            raise NotHomedError(f"{self.transport.name}: stage not homed; home it before moving")
        self._ensure_speed()
        s = self.settings
        here = self.position()
        if s.approach_m > 0 and position_m < here + s.position_tolerance_m:
            pre = max(lo, position_m - s.approach_m)
            if pre < position_m:
                self._move_abs(pre, here)
                here = pre
        self._move_abs(position_m, here)
        reached = self.position()
        if abs(reached - position_m) > max(s.position_tolerance_m, s.microstep_m):
            raise StallError(
                f"{self.transport.name}: reached {reached * 1e3:.4f} mm, target "
                f"{position_m * 1e3:.4f} mm"
            )
        s.clock.sleep(s.settle_s)

    def _move_abs(self, target_m: float, from_m: float) -> None:
        s = self.settings
        timeout = abs(target_m - from_m) / s.speed_m_per_s * 1.5 + s.timeout_margin_s
        self.command(f"move abs {self._steps(target_m)}")
        self._wait_idle(f"move abs {target_m * 1e3:.4f} mm", timeout)

    def _wait_idle(self, what: str, timeout_s: float) -> None:
        clock = self.settings.clock
        t_end = clock.now() + timeout_s
        while True:
            r = self.command("")
            if not r.busy:
                return
            if clock.now() > t_end:
                self.stop()
                raise InstrumentTimeout(
                    f"{self.transport.name}: {what} not finished within {timeout_s:.3g} s; stopped"
                )
            clock.sleep(self.settings.poll_interval_s)

    def stop(self) -> None:
        """Decelerate to a stop (``stop``); does not check flags."""
        s = self.settings
        self.transport.query(f"/{s.device} {s.axis} stop")

    def clear_warnings(self) -> None:
        """``warnings clear`` (after a handled stall/limit fault)."""
        s = self.settings
        self.transport.query(f"/{s.device} {s.axis} warnings clear")

    def snapshot(self) -> dict[str, Any]:
        s = self.settings
        snap: dict[str, Any] = {
            "model": "Zaber (ASCII)",
            "resource": self.transport.name,
            "device": s.device,
            "axis": s.axis,
            "microstep_m": s.microstep_m,
            "speed_m_per_s": s.speed_m_per_s,
            "approach_m": s.approach_m,
            "settle_s": s.settle_s,
            "soft_limits_m": list(s.soft_limits_m) if s.soft_limits_m else None,
        }
        try:
            snap["limits_m"] = list(self.limits())
            snap["position_m"] = self.position()
            snap["homed"] = self.is_homed()
        except InstrumentError as exc:
            snap["error"] = str(exc)
        return snap

    def safe_state(self) -> None:
        """Stop; never raises."""
        try:
            self.stop()
        except Exception as exc:
            log.warning("%s: stop failed: %s", self.transport.name, exc)

    def close(self) -> None:
        self.safe_state()
        self.transport.close()
