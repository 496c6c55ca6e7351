"""The hardware behind the stand-in: devices, their time, and the trigger lines a test drives."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from .constants import TerminalConfiguration

if TYPE_CHECKING:
    from .task import Task


@dataclass(frozen=True)
class DeviceSpec:
    """One multiplexed AI device (defaults: a PCIe-6361-like X Series card).

    ``ai_max_multi_chan_rate`` is the device's aggregate rate, as NI documents it: a task of
    ``n`` channels may sample at ``min(ai_max_single_chan_rate, ai_max_multi_chan_rate / n)``.
    """

    product_type: str = "PCIe-6361"
    serial_num: int = 0x1A2B3C
    ai_channels: int = 16
    ai_max_single_chan_rate: float = 2.0e6
    ai_max_multi_chan_rate: float = 1.0e6
    timebase_Hz: float = 100.0e6
    terminal_cfgs: frozenset[TerminalConfiguration] = frozenset(
        {TerminalConfiguration.RSE, TerminalConfiguration.NRSE, TerminalConfiguration.DIFF}
    )
    default_terminal_cfg: TerminalConfiguration = TerminalConfiguration.DIFF


@dataclass
class Card:
    """Devices by name and the time (s) of the card; tests advance time and fire edges."""

    devices: dict[str, DeviceSpec] = field(default_factory=lambda: {"Dev1": DeviceSpec()})
    t: float = 0.0
    tasks: list[Task] = field(default_factory=list)
    #: every (time, terminal) edge fired, and which tasks took it
    edges: list[tuple[float, str, int]] = field(default_factory=list)
    #: (message, code) of a DaqError that ``Task()`` raises, as DAQmxCreateTask does when the
    #: driver cannot make one; None: tasks are created
    refuse_new_tasks: tuple[str, int] | None = None

    # the Clock protocol (instruments.clock), so the driver can wait on the card's time
    def now(self) -> float:
        return self.t

    def sleep(self, dt_s: float) -> None:
        self.t += max(0.0, float(dt_s))

    def fire(self, terminal: str) -> int:
        """A rising edge on ``terminal`` now; returns how many running tasks took it."""
        taken = sum(1 for task in list(self.tasks) if task._edge(terminal, self.t))
        self.edges.append((self.t, terminal, taken))
        return taken


#: the card the stand-in module talks to (set by ``install``)
CARD: Card = Card()
