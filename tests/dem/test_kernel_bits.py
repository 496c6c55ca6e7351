"""The compiled kernel's bits, pinned: a change of its loop structure that should not change its
arithmetic (a faster pass, a different loop order) must give the same bits, and a change that
does must change ``NUMERICS_VERSION`` and the checksums below together.

The inputs are those of ``simulate`` on the benchmark chain, passed through float32 (so that a
last-bit difference of the host's ``exp``/``sin`` in the model's setup cannot reach the kernel)
and waveform drives made of exact binary fractions (no ``exp``/``cos`` in the kernel), so that
the kernel computes with ``+ - *``, fused multiply-adds, ``max`` and ``sqrt`` only: IEEE
operations with one result on any host."""

from __future__ import annotations

import hashlib
import inspect
from typing import Any

import numpy as np
import pytest

from sim_backend import dem
from sim_backend.dem import kernel, simulation
from sim_backend.dem.spec import benchmark_chain_spec

#: NUMERICS_VERSION these checksums belong to, and sha256 of (velocity, energy) per batch size
PINNED = {
    "version": "4: overlaps from shifted displacements, fused dashpot and stage",
    4: "e45992e720d993c5d9351c1fcd4e5e38be3cdc5c3f9a433330f5e9484a38df80",
    16: "6b7a895c1c9f0664b0525b6ec3eef6cdb1b815920c990cc8ef6a2b5c42377184",
    64: "fe520a7c92b64ccc505cc9e18d69043b2c8986cb23919d58d5c4891104c5a8bf",
}
#: the same with Heun's kicks (``dashpot_kick="heun3"``: pass 3), taken with the kernel before
#: it had chunks of sixteen and summed u' in pass 2
PINNED_HEUN = {
    16: "a1b3f466a6e125682663cb79bb0b0b717597cf89458fe1486363c1add84f2aeb",
    64: "39d7de99cf4e086902e4e462194437eda8166ea5e9c8ad012545cd06792612c9",
}


def _tent(n: int) -> np.ndarray:  # type: ignore[type-arg]
    k = np.arange(n, dtype=np.float64)
    return np.minimum(k, n - 1 - k) / 32.0  # exact binary fractions


def _kernel_args(n_drives: int, kick: str = "midpoint") -> dict[str, Any]:
    """The keyword arguments ``simulate`` gives ``run_batch`` for ``n_drives`` waveform drives
    (both directions, displacement and force) and the dashpot ``kick``, float inputs rounded to
    float32."""
    chain = dem.build_chain(benchmark_chain_spec())
    captured: dict[str, Any] = {}

    def capture(*args: Any) -> None:
        names = list(inspect.signature(kernel.run_batch).parameters)
        captured.update(zip(names, args, strict=False))

    amp = float(np.float32(chain.delta0_m))
    drives = []
    for r in range(n_drives):
        kind = "displacement" if r % 3 else "force"
        scale = amp * (1 + r % 4) if kind == "displacement" else 2.0 * (1 + r % 4)
        drives.append(
            dem.Drive(
                direction="ltr" if r % 2 == 0 else "rtl",
                kind=kind,
                amplitude=scale,
                waveform=(_tent(40 + 8 * (r % 5)), 250e3),
            )
        )
    mp = pytest.MonkeyPatch()
    mp.setattr(simulation, "run_batch", capture)
    mp.setattr(simulation.numba, "get_num_threads", lambda: 1)  # the chunks of one thread
    try:
        dem.simulate(chain, drives, duration_s=0.4e-3, sample_rate_Hz=250e3, dashpot_kick=kick)
    finally:
        mp.undo()
    outputs = ("vel", "disp", "drv", "energy")
    for name, value in captured.items():
        if name in outputs:
            captured[name] = np.zeros_like(value)
        elif isinstance(value, np.ndarray) and value.dtype == np.float64:
            captured[name] = value.astype(np.float32).astype(np.float64)
        elif isinstance(value, float):
            captured[name] = float(np.float32(value))
    return captured


def _checksum(n_drives: int, kick: str = "midpoint") -> str:
    args = _kernel_args(n_drives, kick)
    kernel.run_batch(**args)
    assert np.all(np.isfinite(args["vel"])) and np.abs(args["vel"]).max() > 0
    digest = hashlib.sha256()
    for name in ("vel", "disp", "drv", "energy"):
        digest.update(np.ascontiguousarray(args[name]).tobytes())
    return digest.hexdigest()


@pytest.mark.parametrize("n_drives", [4, 16, 64])
def test_kernel_bits_are_pinned(n_drives: int) -> None:
    """4 drives: chunks of four lanes; 16: chunks of eight (two vectors at a time); 64: chunks
    of sixteen (four vectors at a time in pass 1). The checksums do not depend on the chunks:
    64's was taken with the kernel before it had chunks of sixteen."""
    assert _kernel_args(n_drives)["lane_traj"].shape[1] == {4: 4, 16: 8, 64: 16}[n_drives]
    assert kernel.NUMERICS_VERSION == PINNED["version"], "new numerics: re-pin the checksums"
    assert _checksum(n_drives) == PINNED[n_drives]


@pytest.mark.parametrize("n_drives", [16, 64])
def test_kernel_bits_with_heun_kicks_are_pinned(n_drives: int) -> None:
    """Heun's kicks, in chunks of eight and of sixteen lanes."""
    assert kernel.NUMERICS_VERSION == PINNED["version"], "new numerics: re-pin the checksums"
    assert _checksum(n_drives, "heun3") == PINNED_HEUN[n_drives]
