"""Zaber linear stage, ASCII protocol, positions in metres.

Request ``/<device> <axis> <id> <command>``; reply
``@<device> <axis> <id> <OK|RJ> <IDLE|BUSY> <flag> <data>``, e.g. ``@01 1 07 OK IDLE -- 0``. The
message id (0..99, the protocol's own) ties each reply to its request: a reply that arrives late,
after its request timed out, carries the old id and is discarded instead of being taken as the
answer to the next command. A reply shows one warning flag (``--`` when none), the one of
highest priority (faults ``F*`` before warnings ``W*`` before notices ``N*``); the command
``warnings`` lists them all. ``WR`` no reference position (not homed), ``FS`` stalled and
stopped, ``WL`` unexpected limit switch (both persist until ``warnings clear``), ``FD`` driver
disabled, ``NI`` a move was interrupted. Every ``F*`` flag and ``WL`` is a fault here. Homed means
``WR`` is not among ``warnings`` (a higher flag can hide it in a reply).

Positions travel as microsteps; the size of one depends on the device (an X-LSM's is 0.047625
um at the default resolution of 64 microsteps per step). The bench file names the stage model
or its microstep; :meth:`ZaberStage.connect` reads the device id (``get device.id``, firmware 7;
``get deviceid`` on firmware 6), ``get version``, ``get resolution`` and ``get limit.min/max``,
and refuses a stage that does not match, or whose travel does not hold the cylinder positions.
A stall or limit warning left from before (``FS``, ``WL``) is cleared at connect, logged, and
the stage is homed again before it moves. Speeds travel as ``microsteps/s x 1.6384``
(``maxspeed`` units).
"""

from __future__ import annotations

import logging
import math
import re
import threading
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from instruments.clock import Clock, SystemClock
from instruments.errors import (
    InstrumentError,
    InstrumentTimeout,
    LimitError,
    MoveTimeout,
    NotHomedError,
    ReplyError,
    StallError,
)
from instruments.interfaces import Transport

__all__ = [
    "FULL_STEP_M",
    "SPEED_UNIT",
    "Rejected",
    "ZaberReply",
    "ZaberSettings",
    "ZaberStage",
    "max_speed_m_per_s",
    "microstep_of_model",
    "parse_reply",
]

log = logging.getLogger(__name__)

#: ``maxspeed`` data per (microstep/s)
SPEED_UNIT = 1.6384
#: full-step length (m) of Zaber lead-screw stage families; microstep = full step / resolution.
#: X-LSM and T-LSM: 0.047625 um per microstep at the default resolution 64 (datasheets).
FULL_STEP_M: dict[str, float] = {"X-LSM": 0.047625e-6 * 64, "T-LSM": 0.047625e-6 * 64}
_MODEL_RE = re.compile(r"^([A-Z]+-[A-Z]+?)(\d+)")
#: a reply checksum (``comm.checksum 1``): a colon and two hex digits ending the line
_CHECKSUM_RE = re.compile(r":[0-9A-Fa-f]{2}$")
_REPLY_RE = re.compile(r"^@(\d+)\s+(\d+)\s+(?:(\d+)\s+)?(OK|RJ)\s+(IDLE|BUSY)\s+(\S\S)\s*(.*)$")
#: names of the flags this driver reports (any other ``F*`` is a fault all the same)
_FLAG_NAMES = {
    "FS": "stalled and stopped",
    "FQ": "encoder error",
    "FE": "limit error: a limit sensor cannot be reached or is faulty",
    "FD": "driver disabled",
    "WL": "unexpected limit switch",
    "WR": "no reference position (not homed)",
}
#: events that stay flagged until ``warnings clear``
_LATCHED = ("FS", "WL")


def _is_fault(flag: str) -> bool:
    return flag.startswith("F") or flag == "WL"


def _describe(flag: str) -> str:
    return _FLAG_NAMES.get(flag, "fault" if flag.startswith("F") else "warning")


@dataclass(frozen=True)
class ZaberReply:
    """One parsed reply line."""

    device: int
    axis: int
    ok: bool
    busy: bool
    flag: str
    data: str
    message_id: int | None = None


def max_speed_m_per_s(microstep_m: float, resolution: int) -> float:
    """The firmware-6 protocol manual's ceiling of ``maxspeed`` in m/s: data ``resolution x
    16384``, i.e. 10,000 full steps/s (30.48 mm/s on an X-LSM at any resolution), for a
    microstep of ``microstep_m`` at ``resolution`` microsteps per step."""
    return resolution * 16384 / SPEED_UNIT * microstep_m


def microstep_of_model(model: str, resolution: int) -> tuple[float, float]:
    """(microstep m, nominal travel m) of a Zaber stage ``model`` (e.g. ``"X-LSM500A"``) at
    ``resolution`` microsteps per step; :class:`LimitError` for a family not in
    :data:`FULL_STEP_M` (give the microstep in the bench file instead)."""
    m = _MODEL_RE.match(model.strip().upper())
    if m is None or m.group(1) not in FULL_STEP_M:
        known = ", ".join(sorted(FULL_STEP_M))
        raise LimitError(
            f"stage model {model!r}: microstep unknown (known families: {known}); give "
            "'microstep' with units in the bench file instead, e.g. '0.047625 um'"
        )
    if resolution <= 0:
        raise LimitError(f"stage resolution must be > 0 microsteps per step, got {resolution}")
    return FULL_STEP_M[m.group(1)] / resolution, int(m.group(2)) * 1e-3


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
        int(m.group(3)) if m.group(3) is not None else None,
    )


class Rejected(ReplyError):
    """A command the device answered ``RJ`` (``reason``: the reply's data, e.g. BADDATA)."""

    def __init__(self, message: str, reason: str) -> None:
        super().__init__(message)
        self.reason = reason


@dataclass(frozen=True)
class ZaberSettings:
    """Stage settings from the bench file (SI units).

    Attributes
    ----------
    device, axis:
        Zaber device address and axis number.
    model:
        Stage model (e.g. ``"X-LSM500A"``): gives the microstep (with the resolution read at
        connect) and the nominal travel the device's ``limit.max`` must agree with.
    microstep_m:
        Length of one microstep (m) at ``resolution``, from the stage's datasheet; with a
        ``model`` too, both must agree. One of the two is needed before the stage moves.
    resolution:
        Microsteps per step the bench file's microstep refers to (default 64, the factory
        setting); the device's ``get resolution`` must match it.
    device_id:
        Expected device id (``get device.id``, firmware 6: ``get deviceid``; ``None``: read and
        recorded, not checked).
    message_ids:
        Send a message id with each command and take only the reply that carries it.
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
    stop_timeout_s:
        How long :meth:`ZaberStage.safe_state` waits for the axis to come to rest after
        ``stop`` (s): the manual's axis stays BUSY while it decelerates.
    position_tolerance_m:
        Largest |reached - target| accepted after a move (m).
    clock:
        Time source for polling (the simulated bench injects its simulated clock).
    """

    device: int = 1
    axis: int = 1
    model: str | None = None
    microstep_m: float | None = None
    resolution: int = 64
    device_id: int | None = None
    message_ids: bool = True
    soft_limits_m: tuple[float, float] | None = None
    speed_m_per_s: float = 0.025
    approach_m: float = 0.5e-3
    settle_s: float = 0.2
    poll_interval_s: float = 0.05
    timeout_margin_s: float = 5.0
    home_timeout_s: float = 120.0
    stop_timeout_s: float = 5.0
    position_tolerance_m: float = 2.0e-6
    clock: Clock = field(default_factory=SystemClock, compare=False)

    def __post_init__(self) -> None:
        if self.microstep_m is not None and not (
            math.isfinite(self.microstep_m) and self.microstep_m > 0
        ):
            raise LimitError(f"stage microstep_m must be > 0, got {self.microstep_m!r}")
        for name in ("speed_m_per_s", "poll_interval_s", "home_timeout_s", "stop_timeout_s"):
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
    """A Zaber axis on a :class:`Transport` (implements ``Stage``); positions in metres.

    The microstep is resolved by :meth:`connect` (called before the first move if nobody did):
    nothing moves until the device's identity agrees with the settings.
    """

    def __init__(self, transport: Transport, settings: ZaberSettings | None = None) -> None:
        self.transport = transport
        self.settings = settings or ZaberSettings()
        self._device_limits_m: tuple[float, float] | None = None
        self._speed_set = False
        self._microstep_m: float | None = None
        self._identity: dict[str, Any] | None = None
        self._next_id = 0
        #: a stall or limit warning was cleared at connect: home before the next move
        self._must_home = False
        #: the last safe state got no reply (to its stop or a poll), and nothing since
        self._stop_unanswered = False

    # --- wire ---------------------------------------------------------------------------
    def _message_id(self) -> int:
        mid = self._next_id
        self._next_id = (self._next_id + 1) % 100
        return mid

    def command(self, text: str, *, check_flags: bool = True) -> ZaberReply:
        """Send ``/<dev> <axis> [<id>] <text>``, take the reply carrying the id; a fault flag ->
        :class:`StallError`, RJ -> :class:`ReplyError` naming the reason (a move refused for want
        of a reference: :class:`NotHomedError`). Stale replies (an earlier id) and info/alert
        lines are skipped."""
        s = self.settings
        mid = self._message_id() if s.message_ids else None
        head = f"/{s.device} {s.axis}" + (f" {mid:02d}" if mid is not None else "")
        cmd = f"{head} {text}".rstrip()
        reply = self.transport.query(cmd)
        for _ in range(16):
            if reply.startswith(("#", "!")):  # info and alert messages
                reply = self.transport.read()
                continue
            if _CHECKSUM_RE.search(reply.strip()):
                raise ReplyError(
                    f"{self.transport.name}: the reply {reply!r} to {cmd!r} ends in a checksum "
                    "(the device's comm.checksum is 1), which this driver does not read: set "
                    "comm.checksum to 0 (Zaber Console, or '/1 set comm.checksum 0')"
                )
            try:
                r = parse_reply(reply)
            except ReplyError:
                raise ReplyError(
                    f"{self.transport.name}: malformed reply to {cmd!r}: {reply!r}"
                ) from None
            if mid is not None and r.message_id != mid:
                log.info("%s: discarded stale reply %r (waiting for id %02d)", cmd, reply, mid)
                reply = self.transport.read()
                continue
            break
        else:
            raise ReplyError(f"{self.transport.name}: no reply to {cmd!r} among the lines read")
        self._stop_unanswered = False  # it answers again
        if r.device != s.device:
            raise ReplyError(f"{self.transport.name}: reply to {cmd!r} from device {r.device}")
        if r.axis not in (s.axis, 0):
            raise ReplyError(f"{self.transport.name}: reply to {cmd!r} from axis {r.axis}")
        rejected = "" if r.ok else f"; rejected ({r.data or 'no reason given'})"
        if check_flags and _is_fault(r.flag):
            raise StallError(
                f"{self.transport.name}: {_describe(r.flag)} ({r.flag}) after {cmd!r}{rejected}"
            )
        if not r.ok:
            if r.flag == "WR" and text.startswith("move"):
                raise NotHomedError(f"{self.transport.name}: {cmd!r} rejected: stage not homed")
            flag = "" if r.flag == "--" else f", warning {r.flag} ({_describe(r.flag)})"
            raise Rejected(
                f"{self.transport.name}: {cmd!r} rejected ({r.data or 'no reason given'}{flag})",
                r.data,
            )
        return r

    def warnings(self) -> list[str]:
        """Every active warning flag (``warnings``: a count, then the flags), not only the one a
        reply shows."""
        r = self.command("warnings", check_flags=False)
        words = r.data.split()
        try:
            count = int(words[0])
        except (ValueError, IndexError):
            raise ReplyError(f"{self.transport.name}: 'warnings' answered {r.data!r}") from None
        return words[1 : 1 + count]

    def _get_int(self, setting: str) -> int:
        r = self.command(f"get {setting}")
        try:
            return int(r.data.split()[0])
        except (ValueError, IndexError):
            raise ReplyError(
                f"{self.transport.name}: 'get {setting}' answered {r.data!r}"
            ) from None

    # --- identity -----------------------------------------------------------------------
    def connect(self, positions_m: Sequence[float] = ()) -> dict[str, Any]:
        """Read ``deviceid``, ``resolution``, ``limit.min/max``; resolve the microstep and refuse
        (:class:`LimitError`, one line, nothing moved) when they disagree with the settings or
        when a position of ``positions_m`` (m) is outside the device's travel."""
        s = self.settings
        name = self.transport.name
        flags = self.warnings()  # before anything that a latched flag would fail
        latched = [f for f in flags if f in _LATCHED]
        if latched:
            self.clear_warnings()
            self._must_home = True
            log.warning(
                "%s: cleared %s left from before (%s); the stage is homed before it moves",
                name,
                ", ".join(latched),
                "; ".join(_describe(f) for f in latched),
            )
        faults = [f for f in flags if _is_fault(f) and f not in _LATCHED]
        if faults:
            raise StallError(
                f"{name}: {', '.join(f'{f} ({_describe(f)})' for f in faults)} at connect: "
                "check the stage and its cable (Zaber Console shows the device's state)"
            )
        try:  # firmware 7 names it device.id, firmware 6 deviceid
            device_id = self._get_int("device.id")
        except ReplyError:
            device_id = self._get_int("deviceid")
        try:
            firmware: str | None = self.command("get version").data or None
        except ReplyError:
            firmware = None
        resolution = self._get_int("resolution")
        lo_steps = self._get_int("limit.min")
        hi_steps = self._get_int("limit.max")
        if s.device_id is not None and device_id != s.device_id:
            raise LimitError(
                f"{name}: device id {device_id}, the bench file expects {s.device_id}: "
                "another stage on this port?"
            )
        nominal_m: float | None = None
        step: float | None = None
        if s.model is not None:
            step, nominal_m = microstep_of_model(s.model, resolution)
        if s.microstep_m is not None:
            if resolution != s.resolution:
                raise LimitError(
                    f"{name}: the device runs at resolution {resolution} microsteps/step, the "
                    f"bench file's microstep {s.microstep_m * 1e6:.6g} um is for {s.resolution}"
                )
            if step is not None and abs(step - s.microstep_m) > 1e-6 * step:
                raise LimitError(
                    f"{name}: bench file microstep {s.microstep_m * 1e6:.6g} um disagrees with "
                    f"{s.model} at resolution {resolution} ({step * 1e6:.6g} um)"
                )
            step = s.microstep_m
        if step is None:
            raise LimitError(
                f"{name}: name the stage model (e.g. 'X-LSM500A') or its microstep "
                "(e.g. '0.047625 um') in the bench file before it moves"
            )
        travel = ((lo_steps * step), (hi_steps * step))
        if nominal_m is not None:
            length = travel[1] - travel[0]
            if not 0.9 * nominal_m <= length <= 1.1 * nominal_m + 0.01:
                raise LimitError(
                    f"{name}: the device's travel is {length * 1e3:.4g} mm with a "
                    f"{step * 1e6:.6g} um microstep, {s.model} has {nominal_m * 1e3:.4g} mm: "
                    "wrong model or microstep in the bench file?"
                )
        for i, p in enumerate(positions_m):
            if not travel[0] <= p <= travel[1]:
                raise LimitError(
                    f"{name}: cylinder {i + 1} at {p * 1e3:.4f} mm is outside the device's "
                    f"travel [{travel[0] * 1e3:.4f}, {travel[1] * 1e3:.4f}] mm"
                )
        self._microstep_m = step
        self._device_limits_m = travel
        self._identity = {
            "device_id": device_id,
            "firmware": firmware,
            "model": s.model,
            "resolution": resolution,
            "microstep_m": step,
            "travel_m": list(travel),
        }
        self._check_speed()  # nothing is sent: check promises to read only
        return dict(self._identity)

    def identity(self) -> dict[str, Any]:
        """Device id, model, resolution, microstep (m) and travel (m) as read at connect."""
        if self._identity is None:
            self.connect()
        assert self._identity is not None
        return dict(self._identity)

    @property
    def microstep_m(self) -> float:
        """Length of one microstep (m), resolved at :meth:`connect`."""
        if self._microstep_m is None:
            self.connect()
        assert self._microstep_m is not None
        return self._microstep_m

    def _steps(self, position_m: float) -> int:
        return round(float(position_m) / self.microstep_m)

    # --- Stage interface ----------------------------------------------------------------
    def status(self) -> ZaberReply:
        """The axis status (with the position as data)."""
        return self.command("get pos")

    def is_homed(self) -> bool:
        """``WR`` is not among the device's warnings, and no stall or limit warning was cleared
        at connect since the last :meth:`home`."""
        return "WR" not in self.warnings() and not self._must_home

    def home(self, cancel: threading.Event | None = None) -> None:
        """Home and block until idle (timeout: :meth:`home_timeout_s`); ``cancel`` set meanwhile
        stops the axis and returns at once, not homed (homing may take minutes)."""
        _ = self.microstep_m  # identity checked before anything moves
        self._ensure_speed()  # a refused speed before anything moves, not after the homing
        timeout = self.home_timeout_s()
        self.command("home")
        if not self._wait_idle("home", timeout, cancel):
            return
        left = self.warnings()
        if "WR" in left:  # the homing ended without finding the reference (interrupted)
            raise NotHomedError(
                f"{self.transport.name}: homing ended without a reference (flags "
                f"{' '.join(left)}); home it again"
            )
        self._must_home = False

    def home_time_s(self) -> float | None:
        """The longest homing (s): the whole travel at the speed the device homes at, the
        lesser of ``maxspeed`` (the bench file's: :meth:`home` sets it first) and
        ``limit.approach.maxspeed`` (the protocol manual); None when the device has no
        approach speed setting."""
        try:
            rates = [self._speed_data(), self._get_int("limit.approach.maxspeed")]
        except ReplyError:
            return None
        positive = [r for r in rates if r > 0]
        if not positive or self._device_limits_m is None:
            return None
        slowest_m_per_s = min(positive) / SPEED_UNIT * self.microstep_m
        lo, hi = self._device_limits_m
        return (hi - lo) / slowest_m_per_s

    def home_timeout_s(self) -> float:
        """How long homing may take (s): :meth:`home_time_s` x 1.5 plus the margin; at least
        ``home_timeout_s`` (also when the device has no homing speed settings)."""
        s = self.settings
        longest = self.home_time_s()
        if longest is None:
            return s.home_timeout_s
        return max(s.home_timeout_s, 1.5 * longest + s.timeout_margin_s)

    def _speed_data(self) -> int:
        """The bench file's speed as ``maxspeed`` data."""
        return round(float(self.settings.speed_m_per_s) / self.microstep_m * SPEED_UNIT)

    def _check_speed(self) -> None:
        """Refuse (:class:`LimitError`, nothing sent) a bench-file speed outside the ``maxspeed``
        range of the firmware 6 protocol manual, as Zaber's own wrappers copy it: data 1 to
        resolution x 16384, 10,000 full steps/s, 30.48 mm/s on an X-LSM at any resolution
        (firmware 7's range was not found; its device still checks when the speed is set).
        Before, the speed went out only before the first move, after homing: a speed the device
        refuses failed the run minutes in."""
        data = self._speed_data()
        if not 1 <= data <= self._max_speed_data():
            raise LimitError(
                f"{self.transport.name}: stage.speed {self.settings.speed_m_per_s * 1e3:.4g} mm/s "
                f"in the bench file is outside the stage's range ('maxspeed' data {data}); the "
                f"protocol manual's range ends at {self._max_speed_m_per_s() * 1e3:.4g} mm/s"
            )

    def _ensure_speed(self) -> None:
        """``set maxspeed`` to the bench file's speed, once, before the stage moves; a device
        that refuses it (a firmware with another range) is a :class:`LimitError` naming the
        bench field."""
        if not self._speed_set:
            s = self.settings
            data = self._speed_data()
            try:
                self.command(f"set maxspeed {data}")
            except Rejected as exc:
                raise LimitError(
                    f"{self.transport.name}: stage.speed {s.speed_m_per_s * 1e3:.4g} mm/s in the "
                    f"bench file: the device refused 'set maxspeed {data}' "
                    f"({exc.reason or 'no reason given'}); the protocol manual's range ends at "
                    f"{self._max_speed_m_per_s() * 1e3:.4g} mm/s"
                ) from None
            self._speed_set = True

    def _max_speed_data(self) -> int:
        """The protocol manual's ceiling of ``maxspeed`` data: resolution (as read at connect)
        x 16384."""
        return int((self._identity or {}).get("resolution", self.settings.resolution)) * 16384

    def _max_speed_m_per_s(self) -> float:
        """:meth:`_max_speed_data` in m/s."""
        resolution = int((self._identity or {}).get("resolution", self.settings.resolution))
        return max_speed_m_per_s(self.microstep_m, resolution)

    def speed(self) -> float:
        """Current ``maxspeed`` in m/s."""
        return self._get_int("maxspeed") / SPEED_UNIT * self.microstep_m

    def position(self) -> float:
        return self._get_int("pos") * self.microstep_m

    def limits(self) -> tuple[float, float]:
        """(low, high) m: device ``limit.min/max`` intersected with the soft limits."""
        if self._device_limits_m is None:
            step = self.microstep_m
            if self._device_limits_m is None:
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
        if abs(reached - position_m) > max(s.position_tolerance_m, self.microstep_m):
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

    def _poll_idle(
        self, timeout_s: float, *, check_flags: bool = True, cancel: threading.Event | None = None
    ) -> bool | None:
        """Poll ``get pos`` every ``poll_interval_s`` until the axis is idle (True), ``timeout_s``
        has passed (False) or ``cancel`` is set (None); a fault flag raises with
        ``check_flags``."""
        clock = self.settings.clock
        t_end = clock.now() + timeout_s
        while True:
            if cancel is not None and cancel.is_set():
                return None
            if not self.command("get pos", check_flags=check_flags).busy:
                return True
            if clock.now() > t_end:
                return False
            clock.sleep(self.settings.poll_interval_s)

    def _wait_idle(
        self, what: str, timeout_s: float, cancel: threading.Event | None = None
    ) -> bool:
        """Poll until idle (True); False when ``cancel`` was set (the axis stopped)."""
        idle = self._poll_idle(timeout_s, cancel=cancel)
        if idle:
            return True
        self.stop()
        if idle is None:
            return False
        stopped = "stopped" if self._wait_rest() else "stop sent, still moving"
        raise MoveTimeout(  # it answered every poll: blocked or slow, not a dead link
            f"{self.transport.name}: {what} not finished within {timeout_s:.3g} s though the "
            f"controller answered (axis blocked or too slow?); " + stopped
        )

    def stop(self) -> None:
        """Decelerate to a stop (``stop``, no message id: any reply will do); flags not checked.
        Returns at once: the axis is BUSY until it has decelerated (:meth:`is_moving`)."""
        s = self.settings
        self.transport.query(f"/{s.device} {s.axis} stop")

    def is_moving(self) -> bool:
        """Whether the axis is moving (``get pos`` answers BUSY), decelerating after a stop
        included; flags not checked. After a :meth:`safe_state` whose ``stop`` got no reply it
        raises :class:`InstrumentTimeout` at once (the link is dead: not another timeout)."""
        if self._stop_unanswered:
            raise InstrumentTimeout(f"{self.transport.name}: no reply to 'stop'")
        return self.command("get pos", check_flags=False).busy

    def _wait_rest(self) -> bool:
        """Poll until the axis is at rest (True), for at most ``stop_timeout_s``; flags not
        checked (a stall is a way to rest)."""
        return bool(self._poll_idle(self.settings.stop_timeout_s, check_flags=False))

    def clear_warnings(self) -> list[str]:
        """``warnings clear`` (after a handled stall/limit fault); the flags it cleared. A
        cleared stall or limit fault (FS, WL) leaves the axis to be homed again, as at
        connect: its position may have slipped."""
        r = self.command("warnings clear", check_flags=False)
        cleared = r.data.split()[1:]
        if {"FS", "WL"} & set(cleared):
            self._must_home = True
        return cleared

    def snapshot(self) -> dict[str, Any]:
        s = self.settings
        snap: dict[str, Any] = {
            "model": "Zaber (ASCII)",
            "resource": self.transport.name,
            "device": s.device,
            "axis": s.axis,
            "stage_model": s.model,
            "microstep_m": self._microstep_m,
            "identity": self._identity,
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
        """Stop, and wait for the axis to come to rest (at most ``stop_timeout_s``); never
        raises (a failure is logged; :meth:`is_moving` tells the caller what came of it). After
        a safe state that got no reply, nothing is sent until a command is answered again: each
        try would cost the link's whole timeout (a run's end, ``biafc check``, closing)."""
        if self._stop_unanswered:
            log.warning("%s: no reply to the last 'stop'; not sent again", self.transport.name)
            return
        try:
            self.stop()
            if not self._wait_rest():
                log.warning(
                    "%s: still moving %.3g s after 'stop'",
                    self.transport.name,
                    self.settings.stop_timeout_s,
                )
        except Exception as exc:
            self._stop_unanswered = isinstance(exc, InstrumentTimeout)
            log.warning("%s: stop failed: %s", self.transport.name, exc)

    def close(self) -> None:
        self.safe_state()
        self.transport.close()
