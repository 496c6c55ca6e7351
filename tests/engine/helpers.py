"""Protocol text, a chain header and a killed run for the engine tests (and others)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from protocols.runfile import ChainInfo
from protocols.schema import ProtocolFile, parse_protocol

PROTOCOL = """\
name: fake_scan
directions: both
burst:
  ltr: {f_center: 8 kHz, cycles: 5}
  rtl: {f_center: 6 kHz, cycles: 5}
amplitudes: [1 Vpp, 2 Vpp]
cylinders: [1, 2, 3]
averages: 2
acquisition: {rate: 100 kS/s, duration: 2 ms, pre_trigger: 0.2 ms}
settle: 5 ms
order: [direction, amplitude, cylinder]
on_point_failure: continue
retries: 2
"""


def make_protocol(text: str = PROTOCOL, **replace: str) -> ProtocolFile:
    for old, new in replace.items():
        text = text.replace(old, new)
    return parse_protocol(text, "test_protocol.yaml")


def chain_info(n: int = 31) -> ChainInfo:
    """The chain header of a synthetic run file: ``n`` cylinders graded 90-110 mm, 13.6 mm
    across, F0 = 5 N, flat quasi-band edges (8 and 10 kHz)."""
    return ChainInfo(
        lengths_m=np.linspace(0.09, 0.11, n), diameter_m=0.0136, f0_N=5.0, beta_c=1e9,
        onset_Hz=np.full(n, 8e3), cutoff_Hz=np.full(n, 1e4),
    )  # fmt: skip


def killed_run(folder: Path, points: int = 2) -> Path:
    """``folder/k.h5``: :data:`PROTOCOL` run on the fake bench (``engine.fake_cli``), its writer
    SIGKILLed once ``points`` points of ltr are measured."""
    from .test_cli import _spawn, _wait_done

    proto = folder / "proto.yaml"
    proto.write_text(PROTOCOL)
    path = folder / "k.h5"
    proc = _spawn([str(proto), "--out", str(path), "--seed", "5"])
    try:
        _wait_done(path, points, proc)
    finally:
        proc.kill()
        proc.wait(10)
    return path


def cable_lab_bench(monkeypatch: Any) -> list[tuple[str, str, float]]:
    """The lab bench's transports on a simulated rig, and no NI card: ``connect_bench`` of a
    lab bench file then opens its drivers on emulated instruments. Returns ``(name, resource,
    timeout_s)`` of each transport opened, in order."""
    import daq.digitiser_nidaq
    import instruments.transport
    from sim_backend.simbench import SimWorld, SimWorldConfig

    world = SimWorld(SimWorldConfig())
    opened: list[tuple[str, str, float]] = []

    def open_transport(resource: str, *, name: str, timeout_s: float, **kw: Any) -> Any:
        opened.append((name, resource, timeout_s))
        return world.transport(name)

    class NoCard:
        def __init__(self, device: str, **kw: Any) -> None:
            self.device = device

        def snapshot(self) -> dict[str, Any]:
            return {"device": self.device}

        def close(self) -> None:
            pass

    monkeypatch.setattr(instruments.transport, "open_transport", open_transport)
    monkeypatch.setattr(daq.digitiser_nidaq, "NidaqDigitiser", NoCard)
    return opened


def flip_bytes(path: Path, offset: int, n: int = 8) -> None:
    """Invert ``n`` bytes of the file ``path`` from ``offset`` on (damage on disk)."""
    with open(path, "r+b") as fh:
        fh.seek(offset)
        raw = fh.read(n)
        fh.seek(offset)
        fh.write(bytes(b ^ 0xFF for b in raw))


def fake_free_space(monkeypatch: Any, *values: int) -> list[int]:
    """The disk's free bytes (``daq.store.disk_space.free_bytes``), in turn (the last one from
    then on); returns the list of calls made, one entry each."""
    from daq.store import disk_space

    calls: list[int] = []

    def free(path: object) -> int:
        calls.append(1)
        return values[min(len(calls), len(values)) - 1]

    monkeypatch.setattr(disk_space, "free_bytes", free)
    return calls
