"""Units: one pint registry for the project (instruments/units.py). The ways a person writes a
quantity all parse, to the float of the field's unit; a wrong dimension is one line naming the
field, what was given and what is expected, through a protocol file and the command line."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from instruments.units import DIMENSIONS, UnitError, format_quantity, parse_quantity
from protocols.bench import load_bench, parse_bench
from protocols.schema import parse_protocol

ROOT = Path(__file__).resolve().parents[2]

PROTOCOL = """\
name: t
directions: [ltr]
burst:
  ltr: {f_center: 8.92 kHz, cycles: 5}
amplitudes: [1 um, 2 um]
cylinders: [1, 31]
acquisition: {rate: 200 kS/s, duration: 10 ms}
"""


@pytest.mark.parametrize(
    ("text", "dimension", "value"),
    [
        ("2 µm", "length", 2e-6),  # micro sign
        ("2 μm", "length", 2e-6),  # Greek mu
        ("2 um", "length", 2e-6),
        ("2 micron", "length", 2e-6),
        ("2um", "length", 2e-6),
        ("8.92kHz", "frequency", 8920.0),
        ("8.92 kHz", "frequency", 8920.0),
        ("50 mm/s/V", "velocity_per_volt", 0.05),
        ("0.05 um/V", "length_per_volt", 5e-8),
        ("0.5 N/V", "force_per_volt", 0.5),
        ("1 MS/s", "sample_rate", 1e6),
        ("200 kSa/s", "sample_rate", 2e5),
        ("250 kHz", "sample_rate", 2.5e5),
        ("2 Vpp", "peak_to_peak_voltage", 2.0),
        ("1 Vpk", "peak_to_peak_voltage", 2.0),
        ("100 mVpp", "peak_to_peak_voltage", 0.1),
        ("150 V", "voltage", 150.0),
        ("30 ms", "time", 0.03),
        ("2 min", "time", 120.0),
        ("90 deg", "angle", 1.5707963267948966),
        ("2200 kg/m^3", "density", 2200.0),
        ("2.2 g/cm3", "density", 2200.0),
        ("72 GPa", "pressure", 72e9),
        ("25 mm/s", "velocity", 0.025),
        ("0.17", "dimensionless", 0.17),
    ],
)
def test_the_ways_a_quantity_is_written(text: str, dimension: str, value: float) -> None:
    assert parse_quantity(text, dimension) == pytest.approx(value, rel=1e-12)


@pytest.mark.parametrize(
    ("text", "dimension", "message"),
    [
        ("2 um", "frequency", "f: '2 um' is a length, expected a frequency (Hz, kHz)"),
        ("8.92 kHz", "length", "f: '8.92 kHz' is a frequency, expected a length (m, mm, um)"),
        ("2 um", "length_per_volt", "f: '2 um' is a length, expected a length per volt"),
        ("10", "time", "f: '10' has no unit; write it with one, e.g. '10 s'"),
        ("8.92 kHzz", "frequency", "f: unknown unit 'kHzz' in '8.92 kHzz'; expected a frequency"),
        ("2 V", "peak_to_peak_voltage", "f: '2 V' does not say peak or peak-to-peak"),
        ("1e400 m", "length", "f: value must be finite"),
    ],
)
def test_refusals_are_one_line_naming_field_and_expected_unit(
    text: str, dimension: str, message: str
) -> None:
    with pytest.raises(UnitError) as info:
        parse_quantity(text, dimension, field="f")
    assert str(info.value).startswith(message) and "\n" not in str(info.value)


@pytest.mark.parametrize("text", ["2 m**9**9**9", "9**9**9 m", "2 (m**9)**99", "2 m^9^9"])
def test_no_arithmetic_is_evaluated(text: str) -> None:
    """pint evaluates what it is given: a tower of powers would run for ever."""
    t0 = time.perf_counter()
    with pytest.raises(UnitError, match="cannot read the unit"):
        parse_quantity(text, "length")
    assert time.perf_counter() - t0 < 1.0


@pytest.mark.parametrize("dimension", [d for d in DIMENSIONS if d != "dimensionless"])
def test_formatted_quantities_read_back(dimension: str) -> None:
    text = format_quantity(1.2345e-3, dimension, digits=12)
    assert parse_quantity(text, dimension) == pytest.approx(1.2345e-3, rel=1e-12)


def test_wrong_dimension_in_a_protocol_names_file_line_and_field() -> None:
    text = PROTOCOL.replace("f_center: 8.92 kHz", "f_center: 2 um")
    with pytest.raises(ValueError) as info:
        parse_protocol(text, "p.yaml")
    assert str(info.value) == (
        "p.yaml:4: burst.ltr.f_center: '2 um' is a length, expected a frequency (Hz, kHz)"
    )


def test_wrong_dimension_through_run_protocol(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    from daq.cli import run_protocol as rp

    proto = tmp_path / "p.yaml"
    proto.write_text(PROTOCOL.replace("rate: 200 kS/s", "rate: 200 kHz/V"))
    assert rp.main([str(proto), "--out", str(tmp_path / "o.h5")]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (
        f"run_protocol: error: {proto}:7: acquisition.rate: '200 kHz/V' has unit kHz / V, "
        "expected a sample rate (S/s, kS/s, MS/s)"
    )


def test_amplitudes_in_peak_or_peak_to_peak_volts() -> None:
    pp = parse_protocol(PROTOCOL.replace("[1 um, 2 um]", "[2 Vpp, 100 mVpp]")).protocol
    pk = parse_protocol(PROTOCOL.replace("[1 um, 2 um]", "[1 Vpk, 50 mVpk]")).protocol
    assert pp.amplitude_kind == pk.amplitude_kind == "generator_Vpp"
    assert list(pk.amplitude_values()) == pytest.approx([2.0, 0.1])
    assert list(pp.amplitude_values()) == pytest.approx([2.0, 0.1])
    with pytest.raises(ValueError, match=r":5: amplitudes: .*a bare V is ambiguous"):
        parse_protocol(PROTOCOL.replace("[1 um, 2 um]", "[1 V, 2 V]"), "p.yaml")


def test_bench_quantities_per_volt_and_in_other_spellings() -> None:
    text = load_bench().text
    assert "piezo_stroke: 0.05 um/V" in text
    bench = parse_bench(text.replace("piezo_stroke: 0.05 um/V", "piezo_stroke: 50 nm/V")).bench
    assert bench.amplifier.piezo_stroke == pytest.approx(5e-8, rel=1e-12)
    with pytest.raises(ValueError, match=r"amplifier.piezo_stroke: '0.05 um' is a length, expe"):
        parse_bench(text.replace("piezo_stroke: 0.05 um/V", "piezo_stroke: 0.05 um"))


def _cold(tmp_path: Path) -> dict[str, str]:
    """An environment whose user cache folder is empty: no unit remembered, pint answers."""
    return dict(os.environ, BIAFC_CACHE_DIR=str(tmp_path))


def test_the_registry_is_built_on_first_use_not_at_import(tmp_path: Path) -> None:
    code = (
        "import sys, protocols.schema, protocols.bench; assert 'pint' not in sys.modules; "
        "from instruments.units import parse_quantity; parse_quantity('1 um', 'length'); "
        "assert 'pint' in sys.modules"
    )
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT, env=_cold(tmp_path))


def test_pint_is_read_without_dask(tmp_path: Path) -> None:
    """pint imports dask when it is installed (array support not used here): 0.1 s more at the
    first quantity and a larger heap for every later garbage collection; dask stays importable."""
    code = (
        "import sys; from instruments.units import parse_quantity; parse_quantity('1 um', "
        "'length'); assert 'pint' in sys.modules and 'dask' not in sys.modules, 'dask loaded'; "
        "import importlib.util; assert importlib.util.find_spec('dask') is not None"
    )
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT, env=_cold(tmp_path))
