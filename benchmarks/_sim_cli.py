"""``python -m benchmarks._sim_cli ARGS...``: ``run_protocol ARGS`` on the simulated bench, then
one line ``EMULATOR OUTPUTS 1=0 2=0`` read from the emulated 33500B itself (not through the
driver), so the fault campaign can check from outside that the generator is really off.
``EMULATOR OUTPUTS none`` when the bench was never assembled."""

from __future__ import annotations

import sys
from typing import Any

import daq.bench_assembly
import daq.cli.run_protocol as rp

_made: list[Any] = []
_real = daq.bench_assembly.assemble


def _keep(*args: Any, **kwargs: Any) -> Any:
    inst = _real(*args, **kwargs)
    _made.append(inst)
    return inst


def emulator_outputs(inst: Any) -> dict[int, bool]:
    """The emulated generator's output switches, as the instrument holds them."""
    channels = inst.world._inst.generator.channels
    return {n: bool(c.output_on) for n, c in channels.items()}


def main(argv: list[str]) -> int:
    daq.bench_assembly.assemble = _keep  # type: ignore[assignment]
    try:
        code = rp.main(argv)
    finally:
        if _made:
            states = " ".join(f"{n}={int(on)}" for n, on in emulator_outputs(_made[-1]).items())
        else:
            states = "none"
        print(f"EMULATOR OUTPUTS {states}", flush=True)
    return code


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
