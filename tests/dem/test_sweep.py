"""Streaming sweeps (issue 18): the reduced output equals the full run's, memory stays small."""

from __future__ import annotations

import numpy as np
import pytest

from instruments.burst import Burst
from sim_backend import dem
from sim_backend.dem.sweep import band_metrics, sweep


def _drives(chain: dem.Chain, n: int) -> list[dem.Drive]:
    amps = chain.delta0_m * np.geomspace(0.05, 3.0, n)
    return [
        dem.Drive(d, "displacement", float(a), burst=Burst(8.92e3 if d == "ltr" else 6.63e3, 5.0))
        for d in ("ltr", "rtl")
        for a in amps
    ]


def test_reduced_sweep_equals_the_full_run(chain: dem.Chain) -> None:
    drives = _drives(chain, 5)  # 10 trajectories, blocks of 4: three blocks, the last short
    kw = {"duration_s": 3e-3, "sample_rate_Hz": 250e3}
    full = dem.simulate(chain, drives, record=("velocity",), **kw)
    res = sweep(chain, drives, cylinders=[1, 31], keep="both", reduce=band_metrics,
                block_size=4, **kw)  # fmt: skip
    assert res.meta["blocks"] == 3 and res.meta["finite"]
    assert res.velocity is not None and res.velocity.dtype == np.float32
    ref = full.velocity[:, [0, 30], :]
    # the same kernel, lane for lane: float32 rounding only
    np.testing.assert_allclose(res.velocity, ref, rtol=2e-7, atol=2e-7 * np.abs(ref).max())
    expect = band_metrics(ref, full.time_s)
    for name, value in expect.items():
        np.testing.assert_allclose(res.metrics[name], value, rtol=1e-12, atol=1e-300)
    exact = sweep(chain, drives, cylinders=[31], dtype=np.float64, block_size=3, **kw)
    assert exact.velocity is not None
    np.testing.assert_array_equal(exact.velocity[:, 0], full.velocity[:, 30])


def test_metrics_only_sweep_keeps_a_few_numbers_per_trajectory(chain: dem.Chain) -> None:
    drives = _drives(chain, 6)
    res = sweep(chain, drives, duration_s=30e-3, sample_rate_Hz=250e3, keep="metrics",
                reduce=band_metrics, block_size=8)  # fmt: skip
    assert res.velocity is None
    assert res.metrics["rms_m_per_s"].shape == (12, 1)  # the far end by default
    assert res.meta["kept_bytes_per_trajectory"] < 100
    # one block of 8 far-end traces in flight, not 12 x 31 cylinders
    assert res.meta["in_flight_bytes"] <= 8 * 7501 * 8
    far = res.metrics["peak_frequency_Hz"][:, 0]
    assert np.all((far > 1e3) & (far < 20e3))


def test_far_end_traces_are_under_the_memory_target(chain: dem.Chain) -> None:
    """< 0.7 MB per trajectory for a 30 ms window at 250 kS/s (simulate: 2.2 MB, float64, all
    cylinders); here 30 kB: one cylinder in float32."""
    res = sweep(chain, _drives(chain, 1), duration_s=30e-3, sample_rate_Hz=250e3)
    assert res.meta["kept_bytes_per_trajectory"] < 0.7e6
    assert res.velocity is not None and res.velocity.shape == (2, 1, 7501)


def test_sweep_refuses_bad_requests_in_one_line(chain: dem.Chain) -> None:
    d = _drives(chain, 1)
    for kwargs in ({"keep": "metrics"}, {"block_size": 0}, {"keep": "all"}, {"record": ("drive",)}):
        with pytest.raises(ValueError) as info:
            sweep(chain, d, duration_s=1e-3, **kwargs)  # type: ignore[arg-type]
        assert "\n" not in str(info.value)


def test_sweep_keeps_the_integrators_error_estimate_per_trajectory(chain: dem.Chain) -> None:
    drives = _drives(chain, 3)  # 6 trajectories, blocks of 4
    kw = {"duration_s": 2e-3, "sample_rate_Hz": 250e3}
    full = dem.simulate(chain, drives, cylinders=[31], error_estimate=True, **kw)
    res = sweep(chain, drives, cylinders=[31], keep="metrics", reduce=band_metrics,
                block_size=4, error_estimate=True, **kw)  # fmt: skip
    est = res.metrics["error_estimate_rel"]
    assert est.shape == (6,) and np.all((est > 0) & (est < 1e-3))
    np.testing.assert_array_equal(est, full.meta["error_estimate_rel"])
    assert "error_estimate_rel" not in sweep(chain, drives[:1], keep="metrics",
                                             reduce=band_metrics, **kw).metrics  # fmt: skip
