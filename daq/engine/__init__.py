"""The run engine: protocol + bench -> run file, one state machine for the CLI and the GUI.

>>> engine = RunEngine(protocol_file, bench_file, instruments, "run.h5")   # doctest: +SKIP
>>> engine.subscribe(print)                                                 # doctest: +SKIP
>>> result = engine.run()        # or engine.start() and engine.pause()/resume()/abort()
"""

from daq.engine.engine import PointCheckError, RunEngine, RunResult
from daq.engine.events import EventKind, RunEvent, RunState, Subscriber
from daq.engine.instruments import BenchInstruments
from daq.engine.plan import Plan, Point, make_plan

__all__ = [
    "BenchInstruments",
    "EventKind",
    "Plan",
    "Point",
    "PointCheckError",
    "RunEngine",
    "RunEvent",
    "RunResult",
    "RunState",
    "Subscriber",
    "make_plan",
]
