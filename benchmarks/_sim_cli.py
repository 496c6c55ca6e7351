"""``python -m benchmarks._sim_cli ARGS...``: ``run_protocol ARGS`` on the simulated bench, then
one line ``EMULATOR OUTPUTS 1=0 2=0`` read from the emulated 33500B itself (not through the
driver), so the fault campaign can check from outside that the generator is really off.
``EMULATOR OUTPUTS none`` when the bench was never assembled."""

from __future__ import annotations

import sys
from typing import Any

import daq.cli.run_protocol as rp  # only this before main: Ctrl-C is handled from there on

_made: list[Any] = []


def emulator_outputs(inst: Any) -> dict[int, bool]:
    """The emulated generator's output switches, as the instrument holds them."""
    channels = inst.world._inst.generator.channels
    return {n: bool(c.output_on) for n, c in channels.items()}


def _connect(*args: Any, **kwargs: Any) -> Any:
    """run_protocol's own connect, keeping the assembled bench (imported only now)."""
    import daq.connect

    real = daq.connect.connect_bench

    def keep(*a: Any, **k: Any) -> Any:
        _made.append(real(*a, **k))
        return _made[-1]

    daq.connect.connect_bench = keep  # type: ignore[assignment]
    try:
        return _real_connect(*args, **kwargs)
    finally:
        daq.connect.connect_bench = real  # type: ignore[assignment]


_real_connect = rp._connect


def main(argv: list[str]) -> int:
    rp._connect = _connect  # type: ignore[assignment]
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
