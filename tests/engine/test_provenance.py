"""Provenance (issue 15): a run file records what reproduces it, readable with plain h5py."""

from __future__ import annotations

import json
from pathlib import Path

import h5py

from daq.connect import connect_bench
from daq.engine import RunEngine
from protocols.bench import load_bench
from protocols.schema import load_protocol

ROOT = Path(__file__).resolve().parents[2] / "protocols"


def test_a_sim_run_file_records_what_reproduces_it(tmp_path: Path) -> None:
    pf, bf = load_protocol(ROOT / "smoke.yaml"), load_bench()
    out = tmp_path / "p.h5"
    assert RunEngine(pf, bf, connect_bench(bf, seed=3), out, seed=3).run().status == "complete"
    with h5py.File(out, "r") as f:  # plain h5py, no SWMR, no biafc code
        a = dict(f.attrs)
        snap = json.loads(f["snapshot"].attrs["json"])
        log = [m.decode() for m in f["log"]["message"][:]]
    assert a["protocol_yaml"] == pf.text and a["bench_yaml"] == bf.text
    assert a["git_commit"] == "unknown" or len(a["git_commit"]) == 40
    assert a["git_dirty"] in (-1, 0, 1)
    assert a["python_version"].startswith("3.") and a["host"] and a["software_version"]
    packages = json.loads(a["packages_json"])
    assert packages["h5py"] == h5py.__version__ and "numpy" in packages
    rb = snap["read_back"]  # asked from the (emulated) instruments, not as requested
    assert rb["generator"]["identity"].count(",") == 3
    assert rb["generator"]["output1_on"] is False
    assert rb["vibrometer"]["range"] == bf.bench.vibrometer.range
    assert rb["vibrometer"]["sensitivity_m_per_s_per_V"] > 0
    assert rb["digitiser"]["sample_rate_Hz"] == 200e3
    # every burst as the generator reported holding it, read back after configuration
    armed = [m for m in log if m.startswith("generator channel 1: ltr burst")]
    assert len(armed) == 2, log
    for line in armed:
        assert ", read back " in line and " VPP, offset 0 V, " in line
        assert " Sa/s, load INF, trigger BUS" in line
    model = snap["simulation_model"]
    assert model["seed"] == 3
    assert model["actuator"]["amplifier_gain_V_per_V"] == 20
    assert model["chain_spec"] is not None
