"""An independent model of a Zaber X-LSM500A on the ASCII protocol, written from Zaber's ASCII
protocol manual and the X-LSM datasheet for the tests; it shares nothing with the driver
(``instruments.zaber``) or the project's emulator (``sim_backend.emulators.zaber``).

Manual, in short: a command is ``/<device> <axis> [<message id 0-99>] <command> [<data>]``;
the reply is ``@<device as 2 digits> <axis> [<id>] <OK|RJ> <IDLE|BUSY> <warning flag> <data>``.
``--`` is no warning, ``WR`` no reference position (not homed); ``warnings`` lists the active
flags as a two-digit count and the flags (``01 WR``). Firmware 7 names the id setting
``device.id`` (firmware 6: ``deviceid``). Positions, limits and speeds are
in microsteps; resolution 64 microsteps per step by default. Datasheet: X-LSM microstep
0.047625 um (at 64), travel 500 mm. A move reports BUSY for one status request, then IDLE;
"all movement commands, including stop, put the axis into the BUSY state, while they are being
executed".
"""

from __future__ import annotations

MICROSTEP_UM = 0.047625
TRAVEL_MM = 500.0


class XLSM500A:
    """State: :attr:`pos` (microsteps), :attr:`homed`; :attr:`late` holds replies back."""

    def __init__(self, device_id: int = 50123) -> None:
        self.device_id = device_id
        self.resolution = 64
        self.limit_min = 0
        self.limit_max = int(TRAVEL_MM * 1000 / MICROSTEP_UM)
        self.pos = self.limit_max // 3
        self.maxspeed = 153600
        self.homed = False
        self.busy_polls = 0
        self.late = 0  # the next n replies arrive only with the reply after them
        self._late_lines: list[str] = []
        self.moves: list[int] = []

    def position_um(self) -> float:
        return self.pos * MICROSTEP_UM

    def _answer(self, message_id: str | None, ok: bool, data: str) -> str:
        state = "BUSY" if self.busy_polls > 0 else "IDLE"
        if self.busy_polls > 0:
            self.busy_polls -= 1
        flag = "--" if self.homed else "WR"
        parts = ["@01", "1"] + ([message_id] if message_id is not None else [])
        parts += ["OK" if ok else "RJ", state, flag, data]
        return " ".join(parts)

    def lines_for(self, line: str) -> list[str]:
        """The lines on the wire after ``line`` was sent (late ones first)."""
        reply = self._reply(line)
        if reply is None:
            return []
        if self.late > 0:
            self.late -= 1
            self._late_lines.append(reply)
            return []
        out, self._late_lines = [*self._late_lines, reply], []
        return out

    def _reply(self, line: str) -> str | None:
        words = line.strip().split()
        if not words or not words[0].startswith("/") or words[0][1:] not in ("1", "01", "0"):
            return None
        words = words[1:]
        if words and words[0] in ("1", "0"):
            words = words[1:]
        mid = None
        if words and words[0].isdigit():
            mid, words = words[0], words[1:]
        if not words:
            return self._answer(mid, True, "0")
        if words == ["home"]:
            self.homed, self.pos, self.busy_polls = True, self.limit_min, 1
            return self._answer(mid, True, "0")
        if words == ["warnings"]:
            return self._answer(mid, True, "00" if self.homed else "01 WR")
        if words == ["stop"]:  # a moving axis decelerates: BUSY for one status request more
            self.busy_polls = 2 if self.busy_polls > 0 else 0
            return self._answer(mid, True, "0")
        if words[:2] == ["move", "abs"] and len(words) == 3:
            target = int(words[2])
            if not self.homed or not self.limit_min <= target <= self.limit_max:
                return self._answer(mid, False, "BADDATA")
            self.pos, self.busy_polls = target, 1
            self.moves.append(target)
            return self._answer(mid, True, "0")
        if words[0] == "get" and len(words) == 2:
            values = {
                "device.id": self.device_id,
                "resolution": self.resolution,
                "limit.min": self.limit_min,
                "limit.max": self.limit_max,
                "pos": self.pos,
                "maxspeed": self.maxspeed,
            }
            if words[1] not in values:
                return self._answer(mid, False, "BADCOMMAND")
            return self._answer(mid, True, str(values[words[1]]))
        if words[:2] == ["set", "maxspeed"] and len(words) == 3:
            self.maxspeed = int(words[2])
            return self._answer(mid, True, "0")
        if words[:2] == ["set", "resolution"] and len(words) == 3:
            self.resolution = int(words[2])
            return self._answer(mid, True, "0")
        return self._answer(mid, False, "BADCOMMAND")


class LineLink:
    """A line transport onto the model, as a serial line behaves: what was not read stays in
    the input buffer; a query with nothing to read times out."""

    def __init__(self, model: XLSM500A, name: str = "stage (X-LSM model)") -> None:
        self.model = model
        self.name = name
        self.timeout_s = 1.0
        self._input: list[str] = []

    def write(self, command: str) -> None:
        self._input.extend(self.model.lines_for(command))

    def query(self, command: str) -> str:
        self.write(command)
        return self.read()

    def read(self) -> str:
        from instruments.errors import InstrumentTimeout

        if not self._input:
            raise InstrumentTimeout(f"{self.name}: no reply within {self.timeout_s:g} s")
        return self._input.pop(0)

    def write_block(self, header: str, data: bytes) -> None:  # pragma: no cover - not used
        raise NotImplementedError

    def close(self) -> None:
        pass
