"""The four-lane vectors of the kernel (``sim_backend.dem.simd``), and what the kernel promises
with them: a drive's result does not depend on the lane, the chunk width or the batch."""

from __future__ import annotations

from typing import Any

import numba
import numpy as np
import pytest
from numba.core.errors import TypingError

from instruments.burst import Burst
from sim_backend import dem
from sim_backend.dem import simulation
from sim_backend.dem.kernel_cache import install_cache_locator
from sim_backend.dem.simd import vbcast, vfma, vlane, vload, vmax, vsplat, vsqrt, vstore

install_cache_locator()  # before the decorators below: compiled code to the user's cache folder


@numba.njit(cache=True)
def _elementwise(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:
    """Rows of ``out`` [9, 8]: a+b, a-b, a*b, 2+a, a*3, 1-a, max(a, b), sqrt(|a|), fma(a, b, a)."""
    for g in range(0, a.size, 4):
        x = vload(a, g)
        y = vload(b, g)
        n = a.size
        vstore(out, 0 * n + g, x + y)
        vstore(out, 1 * n + g, x - y)
        vstore(out, 2 * n + g, x * y)
        vstore(out, 3 * n + g, 2.0 + x)
        vstore(out, 4 * n + g, x * 3)
        vstore(out, 5 * n + g, 1.0 - x)
        vstore(out, 6 * n + g, vmax(x, y))
        vstore(out, 7 * n + g, vsqrt(vmax(x, 0.0 - x)))
        vstore(out, 8 * n + g, vfma(x, y, x))


@numba.njit(cache=True)
def _fma_and_lanes(a: float, b: float, c: float) -> tuple[float, float, float, float, float]:
    v = vfma(vsplat(a), vsplat(b), vsplat(c))
    w = vsplat(a) * vsplat(b) + vsplat(c)
    return vlane(v, 0), vlane(v, 3), vlane(w, 2), vlane(vsplat(a), 1), vlane(vsplat(7), 0)


def test_vector_operations_match_numpy() -> None:
    rng = np.random.default_rng(1)
    a = rng.normal(size=8)
    b = rng.normal(size=8)
    out = np.full(9 * 8, np.nan)
    _elementwise(a, b, out)
    want = [a + b, a - b, a * b, 2.0 + a, a * 3, 1.0 - a, np.maximum(a, b), np.sqrt(np.abs(a))]
    np.testing.assert_array_equal(out.reshape(9, 8)[:8], np.array(want))
    np.testing.assert_allclose(out.reshape(9, 8)[8], a * b + a, rtol=1e-15, atol=1e-15)


def test_fma_rounds_once_and_plain_operations_do_not_fuse() -> None:
    """(1 + 2^-30)(1 - 2^-30) - 1 = -2^-60 exactly; rounded after the product it is 0."""
    e = 2.0**-30
    fused, fused_lane3, plain, lane, splat_int = _fma_and_lanes(1.0 + e, 1.0 - e, -1.0)
    assert fused == fused_lane3 == -(2.0**-60)
    assert plain == 0.0
    assert lane == 1.0 + e and splat_int == 7.0


@numba.njit(cache=True)
def _bcast_lanes(a: np.ndarray, i: int) -> tuple[float, float, float, float]:
    v = vbcast(a, i)
    return vlane(v, 0), vlane(v, 1), vlane(v, 2), vlane(v, 3)


def test_vbcast_gives_one_element_in_every_lane() -> None:
    a = np.array([1.5, -2.25, 3.0e-300, np.inf])
    for i in range(4):
        assert _bcast_lanes(a, i) == (a[i],) * 4
    with pytest.raises(TypingError, match="C-contiguous 1-D float64"):
        _bcast_lanes(np.zeros((2, 4)), 0)


def test_vload_refuses_arrays_it_cannot_read_as_lanes() -> None:
    @numba.njit
    def first_lane(x: np.ndarray) -> float:
        return vlane(vload(x, 0), 0)

    assert first_lane(np.arange(4.0)) == 0.0
    with pytest.raises(TypingError, match="C-contiguous 1-D float64"):
        first_lane(np.zeros((2, 4)))
    with pytest.raises(TypingError, match="C-contiguous 1-D float64"):
        first_lane(np.zeros(4, dtype=np.float32))


def _drive(direction: str, amplitude_um: float) -> dem.Drive:
    f = 8.92e3 if direction == "ltr" else 6.63e3
    return dem.Drive(
        direction=direction,
        kind="displacement",
        amplitude=amplitude_um * 1e-6,
        burst=Burst(f, 5.0),
    )


def test_a_drive_gives_the_same_bits_in_any_lane_and_chunk_width(chain: dem.Chain) -> None:
    """Alone (a chunk of 4 lanes, 3 of them padding) and inside a batch of 20 (chunks of 8
    lanes, mixed directions), the same drive gives bit-identical velocities and energies."""
    drive = _drive("ltr", 3.0)
    others = [_drive("ltr" if k % 3 else "rtl", 0.2 + 0.3 * k) for k in range(19)]
    alone = dem.simulate(chain, [drive], duration_s=2e-3, sample_rate_Hz=250e3)
    for pos in (0, 6, 13):  # lane 0 of the first chunk, lane 4 (its second vector), the next chunk
        batch = [*others[:pos], drive, *others[pos:]]
        mixed = dem.simulate(chain, batch, duration_s=2e-3, sample_rate_Hz=250e3)
        np.testing.assert_array_equal(mixed.velocity[pos], alone.velocity[0])
        assert mixed.meta["energy_gain_J"][pos] == alone.meta["energy_gain_J"][0]
    assert np.abs(alone.velocity[0, -1]).max() > 1e-4  # the burst reached the far end


@pytest.mark.parametrize(
    ("chain_name", "kick"),
    [("chain", "midpoint"), ("dashpot_chain", "midpoint"), ("dashpot_chain", "heun3")],
)
def test_a_burst_gives_the_same_bits_beside_bursts_of_its_shape(
    request: pytest.FixtureRequest, chain_name: str, kick: str
) -> None:
    """In chunks of 16 lanes (32 LTR + 16 RTL bursts on one thread) whose bursts differ by
    their amplitude, one lane computes a burst shape a kick and the lanes of the same shape take
    it (``kernel._burst_leads``: bursts of 5 and of 7 cycles here), pass 1 drifts four vectors
    at a time and, with a dashpot, pass 2 sums the velocities: a 7-cycle drive still gives the
    bits it gives alone, as the lane that computes its shape (first lane; first 7-cycle lane of
    the next chunk) or as one that takes it from an earlier lane. Default chain (no dashpot)
    and the dashpot chain with midpoint and Heun kicks."""
    chain = request.getfixturevalue(chain_name)
    drive = dem.Drive("ltr", "displacement", 2.5e-6, burst=Burst(8.92e3, 7.0))
    others = [_drive("ltr" if k % 3 else "rtl", 0.1 + 0.08 * k) for k in range(47)]
    others[2] = dem.Drive("ltr", "displacement", 0.7e-6, burst=Burst(8.92e3, 7.0))
    orient = np.array([0 if d.direction == "ltr" else 1 for d in [drive, *others]])
    assert simulation._lanes(orient, 1)[0].shape[1] == 16
    kw: dict[str, Any] = {"duration_s": 2e-3, "sample_rate_Hz": 250e3, "dashpot_kick": kick}
    alone = dem.simulate(chain, [drive], **kw)
    threads = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        for pos in (0, 9, 40):
            batch = [*others[:pos], drive, *others[pos:]]
            mixed = dem.simulate(chain, batch, **kw)
            np.testing.assert_array_equal(mixed.velocity[pos], alone.velocity[0])
            assert mixed.meta["energy_gain_J"][pos] == alone.meta["energy_gain_J"][0]
    finally:
        numba.set_num_threads(threads)
    assert np.abs(alone.velocity[0, -1]).max() > 1e-5  # the burst reached the far end
