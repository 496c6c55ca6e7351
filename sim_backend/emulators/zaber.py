"""Emulated Zaber axis (ASCII protocol): moves take simulated time on a shared :class:`SimClock`.

Written from Zaber's ASCII protocol manual: ``/<device> <axis> [<message id>] <command>``, reply
``@<device> <axis> [<id>] <OK|RJ> <IDLE|BUSY> <flag> <data>`` (the id echoed when one was sent).
The reply's axis is the command's scope, as in the manual: "The reply scope. 0 for the device
or all axes, 1 onwards for an individual axis" (``/1 get pos``, ``/1 0 home``, ``/1 warnings``
answer ``@01 0 ...``; ``/1 1 get pos`` answers ``@01 1 ...``).
The microstep is the device's own: full-step length / ``resolution`` (default 64), e.g. 0.047625
um on an X-LSM; ``get resolution``, ``get limit.min/max``, ``get version`` answer as the device,
and its id as firmware 7 names it (``get device.id``; ``deviceid`` is firmware 6's name and is
rejected) unless ``firmware=6``. Warning flags: a reply shows the one of highest priority
(faults, then warnings, then notices); ``warnings`` lists them all (``NN F1 F2``) and
``warnings clear`` clears those that are events (``FS`` stalled, ``WL`` unexpected limit,
``NI``), not ``WR`` (no reference position), which only ``home`` clears. The manual: "All
movement commands, including stop, put the axis into the BUSY state, while they are being
executed", and ``NI`` flags a movement command that interrupted another: ``stop`` decelerates a
moving axis at :attr:`ZaberEmulator.accel_m_per_s2` (this emulator's figure, not the
datasheet's) and answers BUSY until it is at rest.
Serial line as shipped: 115200 baud, 8N1 (:attr:`BAUD_RATE`).

State for the world: :meth:`ZaberEmulator.position_m` (at the clock's time), :attr:`homed`,
:meth:`busy`, :attr:`flags`. Faults: :meth:`stall` (stops the axis, flag FS), :meth:`lose_homing`
(flag WR), :meth:`raise_flag` (any flag),
:attr:`responsive`, :attr:`late_replies` (the next n replies miss their request's timeout and
arrive just before the reply to the following command, as after a stall of the link).
"""

from __future__ import annotations

from instruments.clock import Clock

__all__ = ["STAGE_MODELS", "ZaberEmulator"]

BAUD_RATE = 115200
#: the order in which a reply shows one of several flags: faults, then warnings, then notices
_PRIORITY = ("FD", "FQ", "FS", "FE", "WL", "WV", "WT", "WM", "WR", "NI")
#: flags that are events, cleared by ``warnings clear``
_EVENTS = ("FS", "WL", "NI")
#: model -> (device id, full-step length m). The device ids are placeholders of this emulator,
#: not Zaber's numbers; the full step is the datasheet's (X-LSM: 3.048 um = 64 x 0.047625 um).
STAGE_MODELS: dict[str, tuple[int, float]] = {
    "X-LSM500A": (50500, 3.048e-6),
    "X-LSM200A": (50200, 3.048e-6),
}


class ZaberEmulator:
    """One device/axis. Positions in microsteps on the wire; ``microstep_m`` converts."""

    def __init__(
        self,
        clock: Clock,
        *,
        device: int = 1,
        axis: int = 1,
        model: str = "X-LSM500A",
        resolution: int = 64,
        travel_m: tuple[float, float] = (0.0, 0.5),
        speed_m_per_s: float = 0.025,
        home_position_m: float | None = None,
        firmware: int = 7,
        accel_m_per_s2: float = 0.2,
        checksum: bool = False,
    ) -> None:
        self.clock = clock
        self.device = device
        self.axis = axis
        self.model = model
        self.device_id, full_step_m = STAGE_MODELS[model]
        self.resolution = int(resolution)
        microstep_m = full_step_m / self.resolution
        self.microstep_m = microstep_m
        self.late_replies = 0
        #: deceleration after ``stop`` (m/s^2)
        self.accel_m_per_s2 = float(accel_m_per_s2)
        #: ``comm.checksum``: replies end in ``:CC``, two hex digits (here the two's complement
        #: of the low byte of the sum of the characters after ``@``; Zaber's exact rule was not
        #: found, and the driver only recognises the form, to refuse it)
        self.checksum = bool(checksum)
        #: line speed (baud) the device listens at; 115200 as shipped
        self.baud_rate = BAUD_RATE
        self._held: list[str] = []
        self.limit_min = round(float(travel_m[0]) / microstep_m)
        self.limit_max = round(float(travel_m[1]) / microstep_m)
        self.maxspeed = round(float(speed_m_per_s) / microstep_m * 1.6384)
        #: the protocol manual: ``home`` runs at the lesser of this and ``maxspeed``
        self.approach_maxspeed = self.maxspeed
        self.home_steps = (
            self.limit_min
            if home_position_m is None
            else round(float(home_position_m) / microstep_m)
        )
        self.responsive = True
        self._homing = False  # a home move under way: WR clears when it ends
        #: 7: the id is ``device.id``; 6: ``deviceid``
        self.firmware = int(firmware)
        #: every active warning flag
        self.flags: set[str] = {"WR"}
        self._start = (self.limit_min + self.limit_max) // 2
        self._target = self._start
        self._t0 = 0.0
        self._t1 = 0.0
        self._stopping = False  # the motion under way is the deceleration after a stop
        self.commands: list[str] = []
        self._id: int | None = None
        #: the reply scope: 0 for a command to the device (axis 0 or none), else this axis
        self._scope = self.axis

    # --- state for the world ------------------------------------------------------------
    def _steps_now(self) -> float:
        t = self.clock.now()
        if t >= self._t1 or self._t1 <= self._t0:
            return float(self._target)
        f = (t - self._t0) / (self._t1 - self._t0)
        return self._start + f * (self._target - self._start)

    def position_m(self) -> float:
        """Carriage position (m) at the clock's current time."""
        return self._steps_now() * self.microstep_m

    def busy(self) -> bool:
        return self.clock.now() < self._t1

    # --- faults ---------------------------------------------------------------------------
    @property
    def homed(self) -> bool:
        """Whether the device has its reference position (no ``WR``)."""
        self._homing_done()
        return "WR" not in self.flags

    def _homing_done(self) -> None:
        """The manual's example: ``WR`` shows while the home move runs, and clears at its end."""
        if self._homing and not self.busy():
            self._homing = False
            self.flags.discard("WR")

    @property
    def flag(self) -> str:
        """The flag a reply shows: the active one of highest priority, ``--`` when none."""
        self._homing_done()
        ranked = sorted(self.flags, key=lambda f: _PRIORITY.index(f) if f in _PRIORITY else 0)
        return ranked[0] if ranked else "--"

    def raise_flag(self, flag: str) -> None:
        """Raise any warning flag (e.g. ``WV``, a supply voltage out of range)."""
        self.flags.add(flag)

    def stall(self) -> None:
        """Stop where it is now and raise the FS (stalled) flag."""
        self._halt()
        self.flags.add("FS")

    def lose_homing(self) -> None:
        """Forget the reference position (flag WR)."""
        self._homing = False
        self.flags.add("WR")

    def _halt(self) -> None:
        self._homing = False  # a home move stopped short: still no reference
        here = round(self._steps_now())
        self._start = self._target = here
        self._t0 = self._t1 = self.clock.now()
        self._stopping = False

    def _decelerate(self) -> None:
        """``stop`` on a moving axis: from its speed now to rest at :attr:`accel_m_per_s2`
        (time v/a, distance v^2/2a, no farther than the move's target)."""
        now = self.clock.now()
        if now >= self._t1 or self._stopping:  # at rest, or decelerating already
            return
        here = self._steps_now()
        speed = abs(self._target - self._start) / (self._t1 - self._t0)  # microsteps/s
        accel = self.accel_m_per_s2 / self.microstep_m  # microsteps/s^2
        left = abs(self._target - here)
        way = min(speed * speed / (2.0 * accel), left)
        direction = 1.0 if self._target > self._start else -1.0
        self._start = round(here)
        self._target = round(here + direction * way)
        self._t0 = now
        self._t1 = now + (2.0 * way / speed if speed > 0 else 0.0)  # mean speed v/2
        self._stopping = True
        self.flags.add("NI")

    def _go(self, target: int, maxspeed: int | None = None) -> None:
        if self.busy():
            self.flags.add("NI")  # a movement command interrupted another
        here = self._steps_now()
        self._stopping = False
        speed = (self.maxspeed if maxspeed is None else maxspeed) / 1.6384  # microsteps/s
        self._start = round(here)
        self._target = target
        self._t0 = self.clock.now()
        self._t1 = self._t0 + abs(target - here) / max(speed, 1e-9)

    # --- wire -----------------------------------------------------------------------------
    def _reply(self, ok: bool, data: str) -> str:
        status = "BUSY" if self.busy() else "IDLE"
        mid = "" if self._id is None else f"{self._id} "
        verdict = "OK" if ok else "RJ"
        line = f"@{self.device:02d} {self._scope} {mid}{verdict} {status} {self.flag} {data}"
        if self.checksum:
            line += f":{-sum(line[1:].encode('ascii')) & 0xFF:02X}"
        return line

    def handle(self, message: bytes) -> str | None:
        """One request line in; the reply line(s) out (several when late ones arrive first)."""
        reply = self._handle(message)
        if reply is None:
            return None
        if self.late_replies > 0:  # this one misses its request's timeout
            self.late_replies -= 1
            self._held.append(reply)
            return None
        lines, self._held = [*self._held, reply], []
        return "\n".join(lines)

    def _handle(self, message: bytes) -> str | None:
        text = message.decode("ascii", "replace").strip()
        self.commands.append(text)
        self._id = None
        self._scope = self.axis
        if not text.startswith("/"):
            return None
        parts = text[1:].split()
        if len(parts) > 1 and not parts[1].isdigit():  # no axis (``/1 warnings``): the device
            parts.insert(1, "0")
        try:
            dev = int(parts[0]) if parts else 0
            axis = int(parts[1]) if len(parts) > 1 else 0
        except ValueError:
            return None
        if dev not in (0, self.device):
            return None
        if axis == 0:  # device scope: the manual's reply scope is 0
            self._scope = 0
        words = parts[2:]
        if words and words[0].isdigit():  # message id 0..99
            self._id = int(words[0])
            words = words[1:]
            if not 0 <= self._id <= 99:
                self._id = None
                return self._reply(False, "BADMESSAGEID")
        if axis not in (0, self.axis):
            return self._reply(False, "BADAXIS")
        if not words:
            return self._reply(True, "0")
        cmd = words[0]
        if cmd == "home":
            self._go(self.home_steps, min(self.maxspeed, self.approach_maxspeed))
            self._homing = True
            return self._reply(True, "0")
        if cmd == "stop":
            self._homing_done()  # a home move that has ended keeps its reference
            self._homing = False  # one stopped short: still no reference
            self._decelerate()
            return self._reply(True, "0")
        if cmd == "warnings" and words[1:] in ([], ["clear"]):
            self._homing_done()
            listed = sorted(self.flags)
            reply = self._reply(True, " ".join([f"{len(listed):02d}", *listed]))
            if words[1:] == ["clear"]:
                self.flags -= set(_EVENTS)
            return reply
        if cmd == "move" and len(words) == 3 and words[1] == "abs":
            if not self.homed:
                return self._reply(False, "BADDATA")
            if "FS" in self.flags:
                return self._reply(False, "BADDATA")
            try:
                target = int(words[2])
            except ValueError:
                return self._reply(False, "BADDATA")
            if not self.limit_min <= target <= self.limit_max:
                return self._reply(False, "BADDATA")
            self._go(target)
            return self._reply(True, "0")
        if cmd == "get" and len(words) == 2:
            value = {
                "pos": round(self._steps_now()),
                "maxspeed": self.maxspeed,
                "limit.approach.maxspeed": self.approach_maxspeed,
                "limit.min": self.limit_min,
                "limit.max": self.limit_max,
                "device.id" if self.firmware >= 7 else "deviceid": self.device_id,
                "version": "7.29" if self.firmware >= 7 else "6.28",
                "resolution": self.resolution,
                "comm.checksum": int(self.checksum),
            }.get(words[1])
            if value is None:
                return self._reply(False, "BADCOMMAND")
            return self._reply(True, str(value))
        if cmd == "set" and len(words) == 3 and words[1] == "maxspeed":
            try:
                value = int(words[2])
            except ValueError:
                return self._reply(False, "BADDATA")
            if not 1 <= value <= self.resolution * 16384:  # the manual's range of maxspeed
                return self._reply(False, "BADDATA")
            self.maxspeed = value
            return self._reply(True, "0")
        return self._reply(False, "BADCOMMAND")
