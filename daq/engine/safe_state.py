"""Every instrument to its safe state, and what of it could be confirmed: one path for the run's
end (:class:`daq.engine.RunEngine`) and the window's Safe state button.

The generator's outputs are switched off first and read back (``OUTPn?``) last; the stage is
asked after them whether its axis came to rest (a Zaber axis stays BUSY while it decelerates
after ``stop``). An output that is still on or cannot be read back, and an axis still moving,
are *unconfirmed*: the person must switch them off by hand. A stage that does not answer is a
problem only (its move ends by itself within the travel, where an output left on stays on).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

__all__ = ["SafeState", "bring_to_safe_state", "generator_name"]


class SafeState:
    """What :func:`bring_to_safe_state` found: ``problems`` met on the way (to log) and
    ``unconfirmed``: what could not be confirmed safe, each naming the instrument."""

    def __init__(self, problems: list[str], unconfirmed: list[str]) -> None:
        self.problems = problems
        self.unconfirmed = unconfirmed


def generator_name(gen: Any) -> str:
    """``"generator (TCPIP0::...)"``: the generator as its transport names it."""
    where = str(getattr(getattr(gen, "transport", None), "name", ""))
    if "generator" in where.lower():
        return where
    return f"generator ({where})" if where else "generator"


def bring_to_safe_state(instruments: Any, channels: Sequence[int]) -> SafeState:
    """Outputs ``channels`` off, every instrument's ``safe_state()``, the outputs read back,
    then the stage's motion (``instruments``: a ``BenchInstruments``). A generator that already
    failed to answer is not asked twice per output: one timeout is enough to know it cannot
    confirm anything."""
    problems: list[str] = []
    gen = instruments.generator
    dead = False
    for ch in channels:
        try:
            gen.output(ch, False)
        except Exception as exc:
            problems.append(f"generator output {ch} off: {exc}")
            dead = dead or isinstance(exc, TimeoutError)
            break  # safe_state() below tries every output once more
    for name, inst in instruments.all().items():
        if name == "generator" and dead:
            continue
        try:
            inst.safe_state()
        except Exception as exc:
            problems.append(f"{name} safe state: {exc}")
    unconfirmed: list[str] = []
    gname = generator_name(gen)
    for ch in channels:
        if dead:
            unconfirmed.append(f"{gname} output {ch}: it does not answer")
            continue
        try:
            on = bool(gen.output_state(ch))
        except Exception as exc:
            unconfirmed.append(f"{gname} output {ch}: cannot read it back ({exc})")
            dead = dead or isinstance(exc, TimeoutError)
            continue
        if on:
            unconfirmed.append(f"{gname} output {ch}: still ON after OUTP{ch} OFF")
    try:  # after the outputs: the stage decelerates after its stop (its safe state waited)
        if instruments.stage.is_moving():
            unconfirmed.append("stage controller: the axis still moves after 'stop'")
    except Exception as exc:  # a silent stage ends its bounded move by itself
        problems.append(f"stage: cannot read whether it stopped: {exc}")
    return SafeState(problems, unconfirmed)
