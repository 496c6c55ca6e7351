"""Protocol and bench files: the shipped ones load and fit the bench; bad ones are refused with
one line naming the file, the line and the field."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from daq.engine import make_plan
from protocols.bench import load_bench, parse_bench
from protocols.schema import load_protocol, parse_protocol
from protocols.yamlfile import ConfigError

ROOT = Path(__file__).resolve().parents[2] / "protocols"
SHIPPED = ["smoke", "ltr_highamp", "rtl_highamp", "biafc_sweep", "linear_lowamp"]

GOOD = """\
name: t
directions: [ltr]
burst:
  ltr: {f_center: 8.92 kHz, cycles: 5}
amplitudes: [1 um, 2 um]
cylinders: [1, 31]
averages: 2
acquisition:
  rate: 200 kS/s
  duration: 10 ms
  pre_trigger: 1 ms
settle: 10 ms
"""


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_protocols_fit_the_sim_bench(name: str) -> None:
    pf = load_protocol(ROOT / f"{name}.yaml")
    plan = make_plan(pf, load_bench())
    assert plan.n_points >= 1
    assert pf.protocol.name == name


def test_shipped_paper_scans() -> None:
    bench = load_bench()
    ltr = make_plan(load_protocol(ROOT / "ltr_highamp.yaml"), bench)
    rtl = make_plan(load_protocol(ROOT / "rtl_highamp.yaml"), bench)
    assert ltr.directions == ("ltr",) and rtl.directions == ("rtl",)
    assert list(ltr.cylinders) == list(range(1, 32))
    sweep = make_plan(load_protocol(ROOT / "biafc_sweep.yaml"), bench)
    assert sweep.directions == ("ltr", "rtl")
    # from far below the static overlap (~1.15 um) to several times it
    assert sweep.amplitudes[0] < 0.05e-6 and sweep.amplitudes[-1] > 3e-6


def test_quantities_are_si_and_points_follow_the_order() -> None:
    pf = parse_protocol(
        GOOD.replace("settle: 10 ms", "settle: 10 ms\norder: [cylinder, amplitude, direction]")
    )
    p = pf.protocol
    assert p.acquisition.rate == 200e3 and p.acquisition.pre_trigger == pytest.approx(1e-3)
    np.testing.assert_allclose(p.amplitude_values(), [1e-6, 2e-6])
    plan = make_plan(pf, load_bench())
    assert [(q.cylinder, q.amplitude_index) for q in plan.points] == [
        (1, 0),
        (1, 1),
        (31, 0),
        (31, 1),
    ]
    # 1 um of wall displacement per generator volt (peak) on the sim bench: 2 Vpp per um
    np.testing.assert_allclose(plan.generator_Vpp, [2.0, 4.0])
    assert plan.amplitude_units == "m"


def test_amplitude_range_log() -> None:
    text = GOOD.replace("[1 um, 2 um]", "{start: 10 mVpp, stop: 1 Vpp, count: 3, spacing: log}")
    np.testing.assert_allclose(parse_protocol(text).protocol.amplitude_values(), [0.01, 0.1, 1.0])


def _err(text: str, tmp_path: Path) -> str:
    f = tmp_path / "p.yaml"
    f.write_text(text)
    with pytest.raises(ConfigError) as info:
        make_plan(load_protocol(f), load_bench())
    msg = str(info.value)
    assert "\n" not in msg
    assert msg.startswith(f"{f}:")
    return msg


def test_malformed_yaml(tmp_path: Path) -> None:
    msg = _err(GOOD.replace("settle: 10 ms", "settle: [10 ms"), tmp_path)
    assert "malformed YAML" in msg


def test_unknown_key_names_line_and_field(tmp_path: Path) -> None:
    msg = _err(GOOD.replace("  duration: 10 ms", "  duration: 10 ms\n  durration: 5 ms"), tmp_path)
    assert msg.endswith(
        ":11: acquisition.durration: unknown key 'durration'; did you mean 'duration'? "
        "(already set: give that name to change it)"
    )


def test_unitless_number(tmp_path: Path) -> None:
    msg = _err(GOOD.replace("duration: 10 ms", "duration: 10"), tmp_path)
    assert ":10: acquisition.duration:" in msg and "no unit" in msg


def test_unitless_amplitude(tmp_path: Path) -> None:
    msg = _err(GOOD.replace("[1 um, 2 um]", "[1, 2]"), tmp_path)
    assert ":5: amplitudes" in msg


def test_amplitude_above_the_piezo_limit(tmp_path: Path) -> None:
    # 7 um -> 14 Vpp: above the generator's 10 Vpp; 6 V peak * 20 = 120 V at the piezo is fine
    msg = _err(GOOD.replace("[1 um, 2 um]", "[1 um, 7 um]"), tmp_path)
    assert ":5: amplitudes: amplitude 2" in msg and "limit" in msg
    bench = load_bench().bench
    assert bench.amplitude_limit_error(9.0) is None
    low_piezo = parse_bench(load_bench().text.replace("piezo_max: 150 V", "piezo_max: 50 V"))
    assert "at the piezo" in (low_piezo.bench.amplitude_limit_error(9.0) or "")


def test_amplitude_below_the_generator_minimum_is_refused_up_front(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The 33500B plays no less than 2 mVpp at high impedance (it clips and queues -222): a
    protocol asking for less is refused at request time (exit 2), in the protocol's own unit,
    not failed at run time by the generator's read-back."""
    from daq.cli import run_protocol as rp
    from instruments.burst import Burst
    from instruments.errors import LimitError
    from instruments.interfaces import BurstConfig
    from instruments.keysight import GeneratorLimits

    proto = tmp_path / "p.yaml"
    proto.write_text(GOOD.replace("[1 um, 2 um]", "[1 um, 0.5 nm]"))
    code = rp.main([str(proto), "--out", str(tmp_path / "o.h5")])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert f"{proto}:5: amplitudes: amplitude 2 (500 pm) is below 1 nm, the smallest" in err
    assert "below the generator's minimum 0.002 Vpp at high impedance" in err
    assert not (tmp_path / "o.h5").exists()
    assert "below the generator minimum" in (load_bench().bench.amplitude_limit_error(1e-3) or "")
    with pytest.raises(LimitError, match=r"below the generator minimum 0\.002 Vpp"):
        GeneratorLimits(max_piezo_V=150.0, amplifier_gain=20.0).check(
            BurstConfig(Burst(8.92e3, 5.0), amplitude_Vpp=1e-3)
        )


def test_cylinder_not_on_the_bench(tmp_path: Path) -> None:
    assert ":6: cylinders: cylinder 32" in _err(GOOD.replace("[1, 31]", "[1, 32]"), tmp_path)


def test_position_outside_the_stage_travel(tmp_path: Path) -> None:
    text = load_bench().text.replace("pitch: 13.6 mm", "pitch: 16 mm")
    f = tmp_path / "bench.yaml"
    f.write_text(text)
    with pytest.raises(
        ConfigError, match=r"bench.yaml:39: cylinder_positions: cylinder 30 at 484 mm"
    ):
        load_bench(f)


def test_width_or_cycles_not_both(tmp_path: Path) -> None:
    msg = _err(GOOD.replace("cycles: 5}", "cycles: 5, width: 1 ms}"), tmp_path)
    assert ":4: burst.ltr: give exactly one" in msg


def test_bench_file_per_volt_units() -> None:
    b = load_bench().bench
    assert b.amplifier.piezo_stroke == pytest.approx(5e-8)
    assert b.n_cylinders == 31
    with pytest.raises(ConfigError, match="piezo_stroke"):
        parse_bench(load_bench().text.replace("0.05 um/V", "0.05"))


def test_a_burst_too_long_for_the_generator_is_refused_without_sampling_it(
    tmp_path: Path, capsys, monkeypatch
) -> None:  # type: ignore[no-untyped-def]
    """The piezo check samples each burst at the generator's rate (its peaks); a 1 s burst at
    200 MSa/s (2e8 points, the generator holds 1e6) ran out of memory there (8.9 GiB) before
    the check that refuses it."""
    import instruments.burst
    from daq.cli import run_protocol as rp

    sampled: list[float] = []
    real = instruments.burst.burst_samples

    def spy(burst, rate):  # type: ignore[no-untyped-def]
        sampled.append(burst.duration_s * rate)
        return real(burst, rate)

    monkeypatch.setattr(instruments.burst, "burst_samples", spy)
    bench = tmp_path / "bench.yaml"
    bench.write_text(load_bench().text.replace("sample_rate: 1 MSa/s", "sample_rate: 100 MSa/s"))
    proto = tmp_path / "p.yaml"
    proto.write_text(GOOD.replace("cycles: 5", "width: 0.3 s").replace("10 ms", "5 s"))
    code = rp.main([str(proto), "--bench", str(bench), "--out", str(tmp_path / "o.h5")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "1,000,000" in err, err
    assert max(sampled, default=0.0) <= 1e6  # what the generator holds, no more


def test_amplitude_above_the_piezo_limit_via_the_cli(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    from daq.cli import run_protocol as rp

    bench = tmp_path / "bench.yaml"
    bench.write_text(load_bench().text.replace("piezo_max: 150 V", "piezo_max: 50 V"))
    proto = tmp_path / "p.yaml"
    proto.write_text(GOOD.replace("[1 um, 2 um]", "[1 um, 3 um]"))
    code = rp.main([str(proto), "--bench", str(bench), "--out", str(tmp_path / "o.h5")])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert err == (
        f"run_protocol: error: {proto}:5: amplitudes: amplitude 2 (3 um) is above 2.299 um, the "
        "limit of this bench: it gives up to 65.25 V at the piezo, above amplifier.piezo_max "
        "50 V (bench.yaml, at gain 20); the burst's peaks are unequal, so it may reach x1.088 "
        "of half its Vpp"
    )
    assert not (tmp_path / "o.h5").exists()


def test_lab_bench_template_validates_without_touching_instruments() -> None:
    lab = load_bench(ROOT / "benches" / "lab_bench.yaml")
    assert not lab.bench.simulated and lab.bench.simulation is None
    plan = make_plan(load_protocol(ROOT / "ltr_highamp.yaml"), lab)
    assert plan.n_points == 31


def test_shipped_protocol_found_by_name_from_any_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    by_file = load_protocol("ltr_highamp.yaml")
    by_stem = load_protocol("ltr_highamp")
    assert by_file.protocol.name == by_stem.protocol.name == "ltr_highamp"
    # a local file of the same name wins over the shipped one
    local = tmp_path / "ltr_highamp.yaml"
    local.write_text(by_file.doc.text.replace("name: ltr_highamp", "name: my_local_copy"))
    assert load_protocol("ltr_highamp.yaml").protocol.name == "my_local_copy"


def test_unknown_protocol_name_lists_the_shipped_ones(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ConfigError, match=r"no shipped protocol.*smoke"):
        load_protocol("no_such_protocol.yaml")
    with pytest.raises(ConfigError, match="no such file"):
        load_protocol(tmp_path / "sub" / "smoke.yaml")
