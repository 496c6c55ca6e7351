"""The paper's regime by default (issue 17): a narrowband burst, honest damping, ``--set``.

The pinning test runs ``biafc simulate`` with its defaults (no burst option, no chain file) at
0.01 um and 2 um in both directions on the default chain and asserts the linear prohibition
(far/near rms < 1.5 %) and the nonlinear gain (x10 LTR, x100 RTL). A 5-cycle burst or the old
contact dashpot fails it (LTR 3.3 % / RTL 2.4 % and gains x4.8 / x5.5).
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

from daq.cli.biafc import main
from instruments.burst import NAMED_BURSTS, NARROWBAND_CYCLES, Burst
from protocols.runfile import read_run
from protocols.schema import load_protocol, parse_protocol, shipped_protocols
from sim_backend import dem
from sim_backend.dem.spec import DampingSpec, default_chain_spec


def _rms_ratio(path: Path, direction: str) -> float:
    v = read_run(path).scans[direction].velocity[0].astype(np.float64)
    near, far = (v[0], v[-1]) if direction == "ltr" else (v[-1], v[0])
    return float(np.sqrt(np.mean(far**2) / np.mean(near**2)))


@pytest.fixture(scope="module")
def default_ratios(tmp_path_factory: pytest.TempPathFactory) -> dict[tuple[str, str], float]:
    out: dict[tuple[str, str], float] = {}
    folder = tmp_path_factory.mktemp("regime")
    for d in ("ltr", "rtl"):
        for amp in ("0.01um", "2um"):
            path = folder / f"{d}_{amp}.h5"
            argv = ["simulate", "--direction", d, "--amplitude", amp, "--rate", "250 kS/s",
                    "--no-error-estimate", "--out", str(path)]  # fmt: skip
            assert main(argv) == 0
            out[(d, amp)] = _rms_ratio(path, d)
    return out


@pytest.mark.parametrize("direction", ["ltr", "rtl"])
def test_default_simulate_is_linear_prohibition(
    default_ratios: dict[tuple[str, str], float], direction: str
) -> None:
    assert default_ratios[(direction, "0.01um")] < 0.015


@pytest.mark.parametrize(("direction", "gain"), [("ltr", 10.0), ("rtl", 100.0)])
def test_default_simulate_gain_at_2um(
    default_ratios: dict[tuple[str, str], float], direction: str, gain: float
) -> None:
    r = default_ratios
    assert r[(direction, "2um")] / r[(direction, "0.01um")] >= gain


def test_default_burst_is_narrowband() -> None:
    b = Burst(8.92e3)
    assert b.cycles == NARROWBAND_CYCLES == NAMED_BURSTS["narrowband"]
    assert b.sigma_s * 8.92e3 == pytest.approx(3.5)  # sigma = 3.5 carrier periods
    assert b.sigma_f_Hz < 0.5e3  # well inside the band gap, far from 8.0 kHz
    assert NAMED_BURSTS["five_cycle"] == 5.0


@pytest.mark.parametrize("name", sorted(shipped_protocols()))
def test_shipped_protocols_use_the_narrowband_burst_and_hold_it(name: str) -> None:
    proto = load_protocol(name).protocol
    for d in proto.direction_list:
        b = proto.burst[d].burst()
        assert b.cycles == NARROWBAND_CYCLES
        # the window holds the burst (<= 3.2 ms) and its transit (about 10 ms at the far end)
        assert proto.acquisition.duration >= b.duration_s + 5e-3


def _proto(burst: str) -> str:
    return (
        "name: t\ndirections: [ltr]\n"
        f"burst:\n  ltr: {burst}\n"
        "amplitudes: [1 um]\nacquisition: {rate: 200 kS/s, duration: 10 ms}\n"
    )


def test_burst_width_in_cycles_time_frequency_or_by_name() -> None:
    by_cycles = parse_protocol(_proto("{f_center: 8.92 kHz, cycles: 21}")).protocol
    by_name = parse_protocol(_proto("{f_center: 8.92 kHz, shape: narrowband}")).protocol
    five = parse_protocol(_proto("{f_center: 8.92 kHz, shape: five_cycle}")).protocol
    sigma_t = parse_protocol(_proto("{f_center: 8.92 kHz, width: 0.5 ms}")).protocol
    sigma_f = parse_protocol(_proto("{f_center: 8.92 kHz, sigma_f: 318.3099 Hz}")).protocol
    assert by_cycles.burst["ltr"].burst() == by_name.burst["ltr"].burst()
    assert five.burst["ltr"].burst().cycles == 5.0
    assert sigma_f.burst["ltr"].burst().sigma_s == pytest.approx(
        sigma_t.burst["ltr"].burst().sigma_s, rel=1e-6
    )
    with pytest.raises(Exception, match="exactly one"):
        parse_protocol(_proto("{f_center: 8.92 kHz, cycles: 5, sigma_f: 1 kHz}"))
    with pytest.raises(Exception, match="five_cycle"):
        parse_protocol(_proto("{f_center: 8.92 kHz, shape: wide}"))


def test_simulate_burst_options(tmp_path: Path) -> None:
    base = ["simulate", "--direction", "ltr", "--amplitude", "0.1um", "--duration", "3 ms",
            "--rate", "250 kS/s", "--no-error-estimate"]  # fmt: skip
    assert main([*base, "--burst", "five_cycle", "--out", str(tmp_path / "a.h5")]) == 0
    assert read_run(tmp_path / "a.h5").scans["ltr"].cycles == 5.0
    assert main([*base, "--sigma-f", "0.5 kHz", "--out", str(tmp_path / "b.h5")]) == 0
    run = read_run(tmp_path / "b.h5")
    width = run.scans["ltr"].width_s
    assert width is not None and width == pytest.approx(1.0 / (2 * np.pi * 500.0))
    assert run.simulation["burst_sigma_f_Hz"] == pytest.approx(500.0)


def test_default_damping_is_named_and_contact_dashpot_off() -> None:
    spec = default_chain_spec()
    assert spec.damping.contact_dashpot_ratio == 0.0
    assert spec.damping.bending_mode_ratio == pytest.approx(2e-3)
    chain = dem.build_chain(spec)
    assert np.all(chain.contact_dashpot_Ns_per_m() == 0.0)
    # the old names are read as the new ones
    old = DampingSpec.model_validate({"resonator_ratio": 0.01, "contact_ratio": 0.02})
    assert (old.bending_mode_ratio, old.contact_dashpot_ratio) == (0.01, 0.02)
    text = spec.to_yaml()
    assert "bending_mode_ratio" in text and "contact_dashpot_ratio" in text


def test_set_changes_the_chain_and_is_recorded(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "d12.h5"
    argv = ["simulate", "--direction", "ltr", "--amplitude", "1um", "--duration", "3 ms",
            "--rate", "250 kS/s", "--no-error-estimate", "--set", "diameter=12mm",
            "--set", "preload=4N", "--set", "n_modes=4", "--out", str(out)]  # fmt: skip
    assert main(argv) == 0
    run = read_run(out)
    assert run.chain.diameter_m == pytest.approx(12e-3)
    assert run.chain.f0_N == pytest.approx(4.0)
    assert "diameter=12mm" in run.simulation["chain_settings"]
    assert "n_modes: 4" in run.simulation["chain_yaml"]
    capsys.readouterr()
    assert main([*argv[:-1], str(tmp_path / "bad.h5"), "--set", "diameter=12"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "diameter" in err and "unit" in err
    assert main(["bands", "--set", "diameter=15 mm", "--bands", "2"]) == 0
    assert "d = 15 mm" in capsys.readouterr().out
    assert main(["bands", "--set", "no_such_key=1"]) == 2
    assert "no_such_key: unknown key" in capsys.readouterr().err


def test_run_protocol_set_reaches_the_simulated_bench_and_is_recorded(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from daq.cli.run_protocol import main as run_protocol

    out = tmp_path / "smoke_d12.h5"
    argv = ["smoke", "--out", str(out), "--quiet", "--set", "diameter=12mm",
            "--set", "preload=4N"]  # fmt: skip
    assert run_protocol(argv) == 0
    run = read_run(out)
    assert run.chain.diameter_m == pytest.approx(12e-3)
    assert run.chain.f0_N == pytest.approx(4.0)
    with h5py.File(out, "r") as f:
        bench_yaml = str(f.attrs["bench_yaml"])
    assert "diameter=12mm" in bench_yaml and "preload=4N" in bench_yaml
    capsys.readouterr()
    bad = ["smoke", "--out", str(tmp_path / "bad.h5"), "--set", "diameter=-1mm", "--dry-run"]
    assert run_protocol(bad) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "diameter" in err


def test_biafc_regime_and_figures_draw_the_regime(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from analysis.report import write_figures

    out = tmp_path / "regime"
    argv = ["regime", "--out", str(out), "--count", "3", "--from", "0.01um", "--to", "2um",
            "--duration", "12 ms", "--set", "n_modes=3"]  # fmt: skip
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "linear floor" in text and (out / "regime.png").stat().st_size > 10_000
    run = read_run(out / "regime.h5")
    assert set(run.scans) == {"ltr", "rtl"} and run.scans["ltr"].velocity.shape[:2] == (3, 31)
    # biafc figures draws the same figure for any amplitude sweep; one amplitude: left out
    report = write_figures(run, tmp_path / "figs")
    assert (tmp_path / "figs" / "regime.png").exists() and "regime" not in report.skipped
    single = tmp_path / "single.h5"
    one = ["simulate", "--direction", "ltr", "--amplitude", "1um", "--duration", "3 ms",
           "--rate", "250 kS/s", "--no-error-estimate", "--out", str(single)]  # fmt: skip
    assert main(one) == 0
    report = write_figures(read_run(single), tmp_path / "figs1")
    assert "regime" in report.skipped and not (tmp_path / "figs1" / "regime.png").exists()
    assert main(["regime", "--out", str(out)]) == 2  # refuses to overwrite
