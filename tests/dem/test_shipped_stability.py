"""The shipped step-stability verdicts (issue 18): never stale, complete for what ships, used."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from instruments.burst import Burst
from protocols.schema import load_protocol, shipped_protocols
from sim_backend import dem
from sim_backend.dem import beam, shipped_stability, step_limit, verdict_store
from sim_backend.dem.spec import benchmark_chain_spec


def test_every_shipped_verdict_is_recomputed_equal() -> None:
    """The table as `python -m sim_backend.dem.shipped_stability` would write it now: the same
    keys (chain content, step, MODES_VERSION), scan settings and verdicts, to the bit."""
    stored = json.loads(shipped_stability.SHIPPED_FILE.read_text())
    fresh = json.loads(json.dumps(shipped_stability.compute_table()))
    assert fresh == stored
    assert len(stored["verdicts"]) == 4  # 2 chains x 2 rates
    assert {v["chain"] for v in stored["verdicts"].values()} == {"default", "benchmark"}


def test_the_shipped_verdicts_cover_the_shipped_protocols() -> None:
    """Every shipped protocol's rate has a verdict, scanned beyond its largest drive."""
    chain = dem.build_chain(dem.default_chain_spec())
    stored = json.loads(shipped_stability.SHIPPED_FILE.read_text())["verdicts"]
    for name, path in shipped_protocols().items():
        protocol = load_protocol(path).protocol
        rate = protocol.acquisition.rate
        assert rate in shipped_stability.SHIPPED_RATES_HZ, name
        peak = float(np.max(protocol.amplitude_values()))  # m (displacement)
        drive = dem.Drive("ltr", "displacement", peak, burst=Burst(8.92e3))
        need = step_limit.reference_overlap_m(chain, [drive])
        h = shipped_stability.checked_step(chain, rate)
        entry = stored[step_limit.range_key(chain, "blanes-moan4", h)]
        assert entry["scanned_to_m"] >= need and entry["stable_to_m"] >= need, name


def _count_scans(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> list[float]:
    """An empty user cache and memory; the overlaps computed from now on."""
    monkeypatch.setenv("BIAFC_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(step_limit, "_RANGE_CACHE", {})
    monkeypatch.setattr(step_limit, "_STABLE_CACHE", {})
    calls: list[float] = []
    stable_many = step_limit._stable_many

    def counting(chain: dem.Chain, integrator: str, h: float, overlaps: list[float]) -> list[bool]:
        calls.extend(overlaps)
        return stable_many(chain, integrator, h, overlaps)

    certified = step_limit._certified

    def counting_certificates(chain: dem.Chain, integrator: str, h: float, overlap: float) -> bool:
        calls.append(overlap)
        return certified(chain, integrator, h, overlap)

    monkeypatch.setattr(step_limit, "_stable_many", counting)
    monkeypatch.setattr(step_limit, "_certified", counting_certificates)
    return calls


@pytest.mark.parametrize("spec", [dem.default_chain_spec, benchmark_chain_spec])
def test_a_fresh_install_computes_no_verdict_for_a_shipped_chain(
    spec: object, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """simulate with the error estimate (what the simulated bench runs) at the shipped rates:
    the checked step 2h is found in the shipped table (no scan, nothing written to the empty
    user cache); a chain that does not ship is computed, so the count would see a scan."""
    calls = _count_scans(monkeypatch, tmp_path)
    chain = dem.build_chain(spec())  # type: ignore[operator]
    drive = dem.Drive("ltr", "displacement", 4e-6, burst=Burst(8.92e3))
    for rate in shipped_stability.SHIPPED_RATES_HZ:
        res = dem.simulate(chain, [drive], duration_s=2e-4, sample_rate_Hz=rate,
                           error_estimate=True, record=("velocity",))  # fmt: skip
        assert res.meta["error_estimate_method"].startswith("step doubling")
    assert calls == []
    verdict_store.flush()
    assert not (tmp_path / "step-stability.json").exists()
    other = dem.build_chain(dem.load_chain_with_settings(None, ["preload=6 N"]))
    dem.simulate(other, [drive], duration_s=2e-4, sample_rate_Hz=200e3, error_estimate=True,
                 record=("velocity",))  # fmt: skip
    assert len(calls) > 0


def test_a_model_change_misses_the_shipped_table(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """The keys hold MODES_VERSION: another model version computes its own verdict."""
    calls = _count_scans(monkeypatch, tmp_path)
    chain = dem.build_chain(dem.default_chain_spec())
    h = shipped_stability.checked_step(chain, 200e3)
    assert step_limit.stable_up_to(chain, "blanes-moan4", h, 2 * chain.delta0_m)
    assert calls == []
    monkeypatch.setattr(beam, "MODES_VERSION", "another model")
    monkeypatch.setattr(step_limit, "_RANGE_CACHE", {})
    assert step_limit.stable_up_to(chain, "blanes-moan4", h, 2 * chain.delta0_m)
    assert len(calls) > 0
