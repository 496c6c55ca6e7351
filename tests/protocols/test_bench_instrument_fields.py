"""Bench file fields for the instruments' identity and serial lines: the stage's model or
microstep, baud rates (VISA ASRL defaults to 9600; Zaber ASCII and the OFV-5000 ship at 115200)."""

from __future__ import annotations

import pytest

from protocols.bench import default_bench_path, load_bench, parse_bench
from protocols.yamlfile import ConfigError


def test_shipped_benches_name_the_stage_and_the_baud_rates() -> None:
    for name in ("lab_bench.yaml", "sim_bench.yaml"):
        b = load_bench(default_bench_path().parent / name).bench
        assert b.stage.model == "X-LSM500A"
        assert b.stage.baud_rate == 115200 and b.vibrometer.baud_rate == 115200


def _with_stage(stage_lines: str) -> str:
    text = default_bench_path().read_text()
    start = text.index("stage:\n")
    end = text.index("daq:\n")
    return text[:start] + "stage:\n" + stage_lines + text[end:]


def test_microstep_with_units_or_model_is_required() -> None:
    b = parse_bench(
        _with_stage(
            "  resource: sim://stage\n  microstep: 0.047625 um\n  soft_limits: [0 mm, 480 mm]\n"
        )
    ).bench
    assert b.stage.microstep == pytest.approx(0.047625e-6)
    assert b.stage.model is None and b.stage.resolution == 64
    with pytest.raises(ConfigError, match="name the stage 'model'"):
        parse_bench(_with_stage("  resource: sim://stage\n  soft_limits: [0 mm, 480 mm]\n"))
