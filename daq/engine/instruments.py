"""The connected bench: the instruments the run engine drives (typed by the Protocols).

Made by :func:`daq.connect.connect_bench` from a bench file (tests may build one from fakes).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Literal

from instruments.interfaces import Digitiser, FunctionGenerator, Stage, Vibrometer
from protocols.runfile import ChainInfo

__all__ = ["BenchInstruments"]


@dataclass
class BenchInstruments:
    """Everything the engine drives.

    Attributes
    ----------
    generator, vibrometer, stage, digitiser:
        The four instruments (real drivers, drivers on the simulated bench, or test fakes).
    chain:
        The model's view of the chain, written to every run file.
    backend:
        ``"sim"`` or ``"hardware"`` (the run file's ``backend`` attribute).
    sleep:
        Waits ``dt`` seconds. ``None``: wall-clock waits (interrupted by abort). The simulated
        bench passes its clock's ``sleep`` so settling costs no wall time.
    world:
        The simulated world (``sim_backend.simbench.SimWorld``) or ``None``.
    locks:
        A lab bench's instrument locks (:class:`daq.instrument_lock.InstrumentLocks`),
        released by :meth:`close`; ``None`` elsewhere.
    """

    generator: FunctionGenerator
    vibrometer: Vibrometer
    stage: Stage
    digitiser: Digitiser
    chain: ChainInfo
    backend: Literal["sim", "hardware"] = "sim"
    sleep: Callable[[float], None] | None = None
    world: Any = None
    extra_snapshot: dict[str, Any] = field(default_factory=dict)
    locks: Any = None

    def all(self) -> dict[str, Any]:
        return {
            "generator": self.generator,
            "vibrometer": self.vibrometer,
            "stage": self.stage,
            "digitiser": self.digitiser,
        }

    def snapshot(self) -> dict[str, Any]:
        """Every instrument's ``snapshot()`` (an error text where one fails)."""
        out: dict[str, Any] = dict(self.extra_snapshot)
        for name, inst in self.all().items():
            try:
                out[name] = inst.snapshot()
            except Exception as exc:
                out[name] = {"error": f"snapshot failed: {exc}"}
        return out

    def wait(self, dt_s: float, abort: threading.Event) -> bool:
        """Wait ``dt_s``; returns False when ``abort`` was set (then it returns at once)."""
        if abort.is_set():
            return False
        if self.sleep is not None:
            self.sleep(dt_s)
            return not abort.is_set()
        return not abort.wait(dt_s)

    def close(self) -> None:
        for inst in self.all().values():
            try:
                inst.close()
            except Exception:
                pass
        if self.locks is not None:
            self.locks.release()
