"""``python -m engine.fake_cli ARGS...`` (from tests/): run_protocol with the bench replaced by
the fake instruments (slow reads), for the SIGKILL / SIGINT subprocess tests. Prints the fake
generator's output states as ``OUTPUTS {...}`` when the run returns (and writes them to the
file ``FAKE_OUTPUTS_FILE`` names, for a run whose terminal is gone). ``FAKE_CONNECT_S``: seconds
the bench assembly takes (to interrupt it); ``FAKE_ABORT_BOUND_S``: the bound on an abort."""

from __future__ import annotations

import os
import sys
import time

import daq.cli.run_protocol as rp
import daq.connect

from .fakes import FakeWorld, Faults, fake_bench

WORLD = FakeWorld(
    seed=int(os.environ.get("FAKE_SEED", "0")),
    faults=Faults(read_sleep_s=float(os.environ.get("FAKE_READ_S", "0.05"))),
)


def _connect(bf, *, seed=None, faults=None):  # type: ignore[no-untyped-def]
    time.sleep(float(os.environ.get("FAKE_CONNECT_S", "0")))  # a slow connect (or compile)
    WORLD.seed = seed or 0
    return fake_bench(WORLD)


daq.connect.connect_bench = _connect  # type: ignore[assignment]
rp.ABORT_BOUND_S = float(os.environ.get("FAKE_ABORT_BOUND_S", rp.ABORT_BOUND_S))

if __name__ == "__main__":
    code = rp.main(sys.argv[1:])
    if os.environ.get("FAKE_OUTPUTS_FILE"):
        with open(os.environ["FAKE_OUTPUTS_FILE"], "w", encoding="utf-8") as f:
            f.write(f"OUTPUTS {WORLD.outputs}\n")
    print(f"OUTPUTS {WORLD.outputs}", flush=True)
    sys.exit(code)
