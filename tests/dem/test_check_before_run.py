"""``simulate`` checks an explicit step's stability before anything else (the stability
certificate, or the grid where it does not answer; ``step_limit.stable_up_to``), in the caller's
thread: an unstable step is refused before the kernel is loaded or run, the check's errors reach
the caller, and the error estimate's rerun at 2h checks its own step once."""

from __future__ import annotations

import threading
from typing import Any

import numpy as np
import pytest

from instruments.burst import Burst
from sim_backend import dem
from sim_backend.dem import simulation, step_limit
from sim_backend.dem.simulation import StepTooLargeError


class _KernelSpy:
    """``run_batch`` that counts its runs."""

    def __init__(self, real: Any) -> None:
        self.real = real
        self.runs = 0

    def __call__(self, *args: Any) -> Any:
        self.runs += 1
        return self.real(*args)


@pytest.fixture()
def fresh(monkeypatch: pytest.MonkeyPatch) -> dict[str, Any]:
    """As in a new process with an empty cache folder: no verdict known. Records the checks
    (certificates and grid scans: in the caller's thread?, step) and the kernel's runs."""
    monkeypatch.setattr(step_limit, "_RANGE_CACHE", {})
    monkeypatch.setattr(step_limit, "_STABLE_CACHE", {})
    monkeypatch.setattr(step_limit, "_LIMIT_CACHE", {})
    monkeypatch.setattr(step_limit, "_disk_load", lambda key: None)
    monkeypatch.setattr(step_limit, "_disk_store", lambda key, v: None)
    seen: dict[str, Any] = {"scans": [], "kernel": _KernelSpy(simulation.run_batch)}
    monkeypatch.setattr(simulation, "run_batch", seen["kernel"])
    stable_many = step_limit._stable_many

    def spy(chain: dem.Chain, integrator: str, h: float, *args: Any, **kw: Any) -> list[bool]:
        seen["scans"].append((threading.current_thread() is threading.main_thread(), h))
        return stable_many(chain, integrator, h, *args, **kw)

    monkeypatch.setattr(step_limit, "_stable_many", spy)
    certified = step_limit._certified

    def certificate_spy(chain: dem.Chain, integrator: str, h: float, overlap: float) -> bool:
        seen["scans"].append((threading.current_thread() is threading.main_thread(), h))
        return certified(chain, integrator, h, overlap)

    monkeypatch.setattr(step_limit, "_certified", certificate_spy)
    seen["threads"] = threading.active_count()
    return seen


@pytest.fixture(scope="module")
def not_shipped() -> dem.Chain:
    """A chain whose verdicts do not ship (the default with another preload)."""
    return dem.build_chain(dem.load_chain_with_settings(None, ["preload=6 N"]))


def _drive(chain: dem.Chain) -> dem.Drive:
    return dem.Drive("ltr", "displacement", 0.5 * chain.delta0_m, burst=Burst(8.92e3))


def test_an_unstable_step_is_refused_before_any_run(
    fresh: dict[str, Any], not_shipped: dem.Chain
) -> None:
    h_bad = 12e-6  # past every stable band of blanes-moan4 on this chain
    with pytest.raises(StepTooLargeError, match="unstable on this chain"):
        dem.simulate(not_shipped, [_drive(not_shipped)], duration_s=1e-3,
                     sample_rate_Hz=1 / h_bad, dt_s=h_bad)  # fmt: skip
    assert fresh["kernel"].runs == 0
    assert fresh["scans"][0] == (True, pytest.approx(h_bad))  # in the caller's thread
    assert all(main for main, _ in fresh["scans"])
    assert threading.active_count() == fresh["threads"]


def test_the_checks_error_reaches_the_caller_and_nothing_runs(
    fresh: dict[str, Any], not_shipped: dem.Chain, monkeypatch: pytest.MonkeyPatch
) -> None:
    def broken(*args: Any, **kw: Any) -> list[bool]:
        raise RuntimeError("check failed")

    monkeypatch.setattr(step_limit, "_stable_many", broken)
    monkeypatch.setattr(step_limit, "_certified", broken)
    with pytest.raises(RuntimeError, match="check failed"):
        dem.simulate(not_shipped, [_drive(not_shipped)], duration_s=1e-3, dt_s=2e-6)
    assert fresh["kernel"].runs == 0


def test_the_error_estimates_step_is_checked_once_and_then_served_from_memory(
    fresh: dict[str, Any], not_shipped: dem.Chain
) -> None:
    """``simulate(..., error_estimate=True)`` with a rerun step 2h near the edge of the small-step
    regime (0.95 pi / w_top, where the grid decides): the rerun checks its step, and the same
    call again computes no check and gives the same bits."""
    d = _drive(not_shipped)
    rate = 1 / 5.8e-6
    kw: dict[str, Any] = dict(duration_s=2e-3, sample_rate_Hz=rate, dt_s=2.9e-6,
                              error_estimate=True)  # fmt: skip
    res = dem.simulate(not_shipped, [d], **kw)
    h = res.meta["dt_s"]
    h2 = simulation.steps_per_sample(2 * h, rate / 2)[1]
    assert not step_limit.certificate_applies(not_shipped, "blanes-moan4", h2)
    assert step_limit.certificate_applies(not_shipped, "blanes-moan4", h)
    assert [s for _, s in fresh["scans"]][-1] == pytest.approx(h2)
    assert fresh["kernel"].runs == 2  # the run and its rerun at 2h
    scans = len(fresh["scans"])
    again = dem.simulate(not_shipped, [d], **kw)
    assert len(fresh["scans"]) == scans
    assert np.array_equal(again.velocity, res.velocity)
    assert np.array_equal(again.meta["error_estimate_rel"], res.meta["error_estimate_rel"])


def test_a_fresh_process_refuses_an_unstable_step_without_loading_the_kernel() -> None:
    """In a new process (the kernel not loaded, no verdict on disk) an unstable step is refused
    before the kernel is loaded: a refusal costs the check, not the kernel's load (about 0.25 s
    from the cache folder, a compilation on a fresh install). Before, the check ran in a thread
    beside the kernel's load, and the refusal came after it."""
    import json
    import subprocess
    import sys
    from pathlib import Path

    probe = """
import json, threading
from instruments.burst import Burst
from sim_backend import dem
from sim_backend.dem import kernel_cache, simulation, step_limit
step_limit._disk_load = lambda key: None
step_limit._disk_store = lambda key, v: None
chain = dem.build_chain(dem.load_chain_with_settings(None, ["preload=6 N"]))
d = dem.Drive("ltr", "displacement", 0.5 * chain.delta0_m, burst=Burst(8.92e3))
loaded_before = kernel_cache.kernel_loaded()
try:
    dem.simulate(chain, [d], duration_s=1e-3, sample_rate_Hz=1 / 12e-6, dt_s=12e-6)
    refused = False
except simulation.StepTooLargeError:
    refused = True
print(json.dumps({"refused": refused, "loaded_before": loaded_before,
                  "loaded_after": kernel_cache.kernel_loaded(),
                  "threads": threading.active_count()}))
"""
    root = Path(__file__).resolve().parents[2]
    out = subprocess.run([sys.executable, "-c", probe], cwd=root, capture_output=True,
                         text=True, check=True, timeout=600)  # fmt: skip
    got = json.loads(out.stdout.strip().splitlines()[-1])
    assert got == {"refused": True, "loaded_before": False, "loaded_after": False, "threads": 1}
