"""``nidaqmx.Task`` for finite, digitally triggered analog input, with NI-DAQmx's task states."""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from enum import IntEnum
from typing import Any

from . import card as _card
from .constants import AcquisitionType, Edge, TaskMode, TerminalConfiguration, VoltageUnits
from .errors import DaqError, DaqReadError, DaqResourceWarning

NUM_SAMPLES_UNSET = object()


class State(IntEnum):
    """NI-DAQmx task states, in the order a task goes through them."""

    UNVERIFIED = 0
    VERIFIED = 1
    RESERVED = 2
    COMMITTED = 3
    RUNNING = 4


@dataclass
class _Chan:
    physical: str
    device: str
    terminal_config: TerminalConfiguration
    min_val: float
    max_val: float


class Task:
    _count = 0

    def __init__(self, new_task_name: str = "") -> None:
        if _card.CARD.refuse_new_tasks is not None:
            raise DaqError(*_card.CARD.refuse_new_tasks)
        Task._count += 1
        self._card = _card.CARD
        self._name = new_task_name or f"_unnamedTask<{Task._count}>"
        self._handle: object | None = object()
        self._state = State.UNVERIFIED
        self._base = State.UNVERIFIED  # where stop() returns to
        self._chans: list[_Chan] = []
        self._rate: float | None = None
        self._n = 0
        self._mode: AcquisitionType | None = None
        self._start_trig: str | None = None
        self._ref_trig: tuple[str, int] | None = None
        self._t_start = 0.0
        self._t_trig: float | None = None
        self._read_done = False
        self.ai_channels = _AIChannels(self)
        self.timing = _Timing(self)
        self.triggers = _Triggers(self)
        self.in_stream = _InStream(self)
        self._card.tasks.append(self)

    # --- state ----------------------------------------------------------------------------------
    @property
    def name(self) -> str:
        self._valid()
        return self._name

    @property
    def state(self) -> State | None:
        """Test hook: the task state (``None`` once cleared)."""
        return None if self._handle is None else self._state

    def _valid(self) -> None:
        if self._handle is None:
            raise DaqError("Task specified is invalid or does not exist.", -200088)

    def _not_running(self) -> None:
        if self._state is State.RUNNING:
            raise DaqError(
                "Specified operation cannot be performed while the task is running.",
                -200479,
                self._name,
            )

    def _changed(self) -> None:
        self._valid()
        self._not_running()
        self._state = self._base = State.UNVERIFIED

    def _device(self) -> Any:
        return self._card.devices[self._chans[0].device]

    def _max_rate(self) -> float:
        dev = self._device()
        n = len(self._chans)
        return float(min(dev.ai_max_single_chan_rate, dev.ai_max_multi_chan_rate / n))

    def _verify(self) -> None:
        if self._state >= State.VERIFIED:
            return
        if not self._chans:
            raise DaqError("Task contains no channels.", -200077, self._name)
        if self._rate is None or self._mode is not AcquisitionType.FINITE:
            raise DaqError("Sample clock timing must be configured.", -200077, self._name)
        dev = self._device()
        for ch in self._chans:
            cfg = ch.terminal_config
            if cfg is not TerminalConfiguration.DEFAULT and cfg not in dev.terminal_cfgs:
                raise DaqError(
                    f"Requested value is not a supported value for this property.\n"
                    f"Property: AI.TermCfg\nRequested Value: {cfg.name}\nChannel Name: "
                    f"{ch.physical}",
                    -200077,
                    self._name,
                )
        limit = self._max_rate()
        if self._rate > limit * (1 + 1e-12):
            raise DaqError(
                f"Sample rate exceeds the maximum sample rate for the number of channels "
                f"specified.\nRequested: {self._rate:g}\nMaximum: {limit:g}",
                -200332,
                self._name,
            )
        if self._ref_trig is not None and not 2 <= self._ref_trig[1] < self._n:
            raise DaqError("Pretrigger samples out of range.", -200077, self._name)
        self._state = State.VERIFIED

    def _reserve(self) -> None:
        """A device's analog inputs serve one task at a time: reserving, committing or starting
        a task while another on the same device holds them (reserved, committed or running)
        fails with -50103, as DAQmx does (creating the task never does)."""
        mine = {c.device.lower() for c in self._chans}
        for other in self._card.tasks:
            if other is self or other._handle is None or other._state < State.RESERVED:
                continue
            if mine & {c.device.lower() for c in other._chans}:
                raise DaqError(
                    "The specified resource is reserved. The operation could not be completed "
                    f"as specified.\nTask Name: {self._name}",
                    -50103,
                    self._name,
                )

    def control(self, action: TaskMode) -> None:
        self._valid()
        if action is TaskMode.TASK_START:
            self.start()
        elif action is TaskMode.TASK_STOP:
            self.stop()
        elif action is TaskMode.TASK_ABORT:
            if self._state is State.RUNNING:
                self._state = self._base = State.VERIFIED
        elif action is TaskMode.TASK_UNRESERVE:
            self._not_running()
            self._state = self._base = min(self._state, State.VERIFIED)
        else:
            self._not_running()
            self._verify()
            target = {
                TaskMode.TASK_VERIFY: State.VERIFIED,
                TaskMode.TASK_RESERVE: State.RESERVED,
                TaskMode.TASK_COMMIT: State.COMMITTED,
            }[action]
            if target >= State.RESERVED and self._state < State.RESERVED:
                self._reserve()
            self._state = self._base = max(self._state, target)

    def start(self) -> None:
        self._valid()
        self._not_running()
        self._verify()
        if self._state < State.RESERVED:
            self._reserve()
        self._base = max(self._state, State.VERIFIED)
        self._state = State.RUNNING
        self._t_start = self._card.now()
        self._t_trig = None
        self._read_done = False

    def stop(self) -> None:
        self._valid()
        if self._state is State.RUNNING:
            self._state = self._base

    def is_task_done(self) -> bool:
        self._valid()
        if self._state is not State.RUNNING:
            return True
        t_end = self._t_end()
        return t_end is not None and t_end <= self._card.now()

    def close(self) -> None:
        if self._handle is None:
            warnings.warn(
                f'Attempted to close NI-DAQmx task of name "{self._name}" but task was '
                "already closed.",
                DaqResourceWarning,
                stacklevel=2,
            )
            return
        self._handle = None
        if self in self._card.tasks:
            self._card.tasks.remove(self)

    clear = close

    def __enter__(self) -> Task:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # --- acquisition ----------------------------------------------------------------------------
    def _edge(self, terminal: str, t: float) -> bool:
        if self._handle is None or self._state is not State.RUNNING or self._t_trig is not None:
            return False
        assert self._rate is not None
        if self._ref_trig is not None:
            source, pretrigger = self._ref_trig
            if source != terminal:
                return False
            # the device looks for the reference trigger only once it holds the pretrigger
            if math.floor((t - self._t_start) * self._rate + 1e-9) < pretrigger:
                return False
        elif self._start_trig != terminal:
            return False
        self._t_trig = t
        return True

    def _t_end(self) -> float | None:
        if self._t_trig is None:
            return None
        assert self._rate is not None
        pre = self._ref_trig[1] if self._ref_trig is not None else 0
        return self._t_trig + (self._n - pre) / self._rate

    def _acquired(self) -> int:
        if self._state is not State.RUNNING:
            return 0
        assert self._rate is not None
        now = self._card.now()
        if self._ref_trig is None:
            if self._t_trig is None:
                return 0
            return min(self._n, math.floor((now - self._t_trig) * self._rate + 1e-9))
        t_end = self._t_end()
        t = now if t_end is None else min(now, t_end)
        return math.floor((t - self._t_start) * self._rate + 1e-9)

    def read(
        self, number_of_samples_per_channel: Any = NUM_SAMPLES_UNSET, timeout: float = 10.0
    ) -> Any:
        """``[channel][sample]``: channel 0 is the time from the trigger in ms, channel 1 is 1 V
        from the trigger on, 0 V before (so a test sees where the trigger fell)."""
        self._valid()
        autostart = self._state is not State.RUNNING
        if autostart:
            self.start()
        try:
            n = (
                self._n
                if number_of_samples_per_channel is NUM_SAMPLES_UNSET
                else (int(number_of_samples_per_channel))
            )
            if self._read_done:
                raise DaqReadError(
                    "Samples will never be available: the finite acquisition was read.",
                    -200278,
                    0,
                    self._name,
                )
            t_end = self._t_end()
            now = self._card.now()
            if t_end is None or t_end > now + timeout:
                self._card.sleep(timeout)
                raise DaqReadError(
                    "Some or all of the samples requested have not yet been acquired.\n"
                    "To wait for the samples to become available use a longer read timeout "
                    "or read later in your program.\n"
                    f"Attempted to Read Sample: 0\nTimeout Specified: {timeout:g}",
                    -200284,
                    0,
                    self._name,
                )
            self._card.sleep(max(0.0, t_end - now))
            assert self._rate is not None
            pre = self._ref_trig[1] if self._ref_trig is not None else 0
            t_ms = [(i - pre) / self._rate * 1e3 for i in range(n)]
            self._read_done = True
            data = [t_ms, [1.0 if t >= 0 else 0.0 for t in t_ms]]
            return data[: len(self._chans)]
        finally:
            if autostart and self._handle is not None:
                self.stop()


class _AIChannels:
    def __init__(self, task: Task) -> None:
        self._task = task

    def add_ai_voltage_chan(
        self,
        physical_channel: str,
        name_to_assign_to_channel: str = "",
        terminal_config: TerminalConfiguration = TerminalConfiguration.DEFAULT,
        min_val: float = -5.0,
        max_val: float = 5.0,
        units: VoltageUnits = VoltageUnits.VOLTS,
        custom_scale_name: str = "",
    ) -> _Chan:
        task = self._task
        task._changed()
        device, _, line = physical_channel.partition("/")
        spec = task._card.devices.get(device)
        if spec is None:
            raise DaqError(f"Device identifier is invalid.\nDevice: {device}", -200220)
        if not (line.startswith("ai") and line[2:].isdigit() and int(line[2:]) < spec.ai_channels):
            raise DaqError(
                f"Physical channel specified does not exist on this device.\n"
                f"Physical Channel Name: {physical_channel}",
                -200170,
                task._name,
            )
        if not isinstance(terminal_config, TerminalConfiguration):
            raise TypeError("terminal_config must be a nidaqmx.constants.TerminalConfiguration")
        cfg = (
            spec.default_terminal_cfg
            if terminal_config is TerminalConfiguration.DEFAULT
            else (terminal_config)
        )
        ch = _Chan(physical_channel, device, cfg, float(min_val), float(max_val))
        task._chans.append(ch)
        return ch


class _Timing:
    def __init__(self, task: Task) -> None:
        self._task = task

    def cfg_samp_clk_timing(
        self,
        rate: float,
        source: str = "",
        active_edge: Edge = Edge.RISING,
        sample_mode: AcquisitionType = AcquisitionType.FINITE,
        samps_per_chan: int = 1000,
    ) -> None:
        task = self._task
        task._changed()
        if not task._chans:
            raise DaqError("Add channels before configuring timing.", -200077, task._name)
        tb = float(task._device().timebase_Hz)
        divisor = max(1, math.floor(tb / float(rate) + 1e-9))  # AI: coerced up to tb / divisor
        task._rate = tb / divisor
        task._mode = sample_mode
        task._n = int(samps_per_chan)

    @property
    def samp_clk_rate(self) -> float:
        self._task._valid()
        if self._task._rate is None:
            raise DaqError("Sample clock rate not specified.", -200077)
        return self._task._rate

    @property
    def samp_clk_max_rate(self) -> float:
        self._task._valid()
        return self._task._max_rate()

    @property
    def samp_quant_samp_per_chan(self) -> int:
        self._task._valid()
        return self._task._n


class _StartTrigger:
    def __init__(self, task: Task) -> None:
        self._task = task

    def cfg_dig_edge_start_trig(
        self, trigger_source: str, trigger_edge: Edge = Edge.RISING
    ) -> None:
        self._task._changed()
        self._task._start_trig = trigger_source


class _ReferenceTrigger:
    def __init__(self, task: Task) -> None:
        self._task = task

    def cfg_dig_edge_ref_trig(
        self, trigger_source: str, pretrigger_samples: int, trigger_edge: Edge = Edge.RISING
    ) -> None:
        self._task._changed()
        self._task._ref_trig = (trigger_source, int(pretrigger_samples))

    @property
    def pretrig_samples(self) -> int:
        self._task._valid()
        return 0 if self._task._ref_trig is None else self._task._ref_trig[1]


class _Triggers:
    def __init__(self, task: Task) -> None:
        self.start_trigger = _StartTrigger(task)
        self.reference_trigger = _ReferenceTrigger(task)


class _InStream:
    def __init__(self, task: Task) -> None:
        self._task = task

    @property
    def total_samp_per_chan_acquired(self) -> int:
        self._task._valid()
        return self._task._acquired()
