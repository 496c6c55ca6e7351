"""A stand-in for the ``nidaqmx`` package, written from NI's documentation, for testing the NI
digitiser without a card (inject it with :func:`install`).

It is strict where a real card is, and where the driver could be wrong:

- a task goes through NI-DAQmx's task states (unverified -> verified -> reserved -> committed ->
  running); ``stop()`` returns it to the state it was in before ``start()``; starting a running
  task, or changing it while running, is DAQmx error -200479;
- a cleared (closed) task is invalid: every use is DAQmx error -200088; a second ``close()``
  only warns (``DaqResourceWarning``), as nidaqmx-python does;
- ``read()`` on a running task whose trigger has not come raises ``DaqReadError`` -200284
  (samples not yet available) after its timeout, and the task stays running;
- the sample clock is the device's timebase divided by an integer: an analog-input rate is
  coerced up to ``timebase / floor(timebase / rate)`` (NI KB "How is the actual sample rate
  determined"), readable at once from ``timing.samp_clk_rate``; above the task's maximum
  (``min(ai_max_single_chan_rate, ai_max_multi_chan_rate / n_channels)`` on a multiplexed
  device) the task does not verify (-200332);
- with a reference trigger, the device looks for the trigger only once it has acquired the
  pretrigger samples; an edge before that is ignored (NI M/X Series manuals, "AI Reference
  Trigger Signal");
- a terminal configuration the device does not support does not verify (-200077).

Time is the test's :class:`Card` clock: acquisition advances with it, and a read that waits
advances it.
"""

from __future__ import annotations

import sys
import types
from typing import Any

from . import constants, error_codes, errors, system
from .card import Card, DeviceSpec
from .errors import DaqError, DaqReadError, DaqResourceWarning, DaqWarning
from .task import Task

__all__ = [
    "Card",
    "DaqError",
    "DaqReadError",
    "DaqResourceWarning",
    "DaqWarning",
    "DeviceSpec",
    "Task",
    "constants",
    "error_codes",
    "errors",
    "install",
    "system",
]

_SUBMODULES = ("constants", "error_codes", "errors", "system")


def install(monkeypatch: Any, card: Card) -> types.ModuleType:
    """Make ``import nidaqmx`` (and its submodules) give this stand-in, on ``card``."""
    from . import card as card_module

    pkg = sys.modules[__name__]
    monkeypatch.setattr(card_module, "CARD", card)
    monkeypatch.setitem(sys.modules, "nidaqmx", pkg)
    for name in _SUBMODULES:
        monkeypatch.setitem(sys.modules, f"nidaqmx.{name}", getattr(pkg, name))
    return pkg
