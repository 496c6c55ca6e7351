"""The asymmetry sweep: its result object, figure and JSON (synthetic), and its inputs."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from analysis.alpha_sweep import (
    AlphaSweepResult,
    format_alpha_sweep,
    parse_amplitude,
    run_alpha_sweep,
    write_alpha_sweep,
)


def _result() -> AlphaSweepResult:
    alphas = np.array([0.1, 0.2, 0.3])
    freq = np.linspace(3000.0, 13000.0, 401)
    r = AlphaSweepResult(
        alphas, alphas + 0.01, {"ltr": 8920.0, "rtl": 6630.0}, ("displacement", 4e-6), 8e-3, freq
    )
    for d, f_in, sign in (("ltr", 8920.0, -1), ("rtl", 6630.0, 1)):
        out = f_in + sign * np.array([300.0, 800.0, 1300.0])
        r.magnitude[d] = np.exp(-(((freq[None, :] - out[:, None]) / 300.0) ** 2))
        r.output_Hz[d] = out
        r.expected_Hz[d] = out + 10.0
        r.transmission[d] = np.array([0.3, 0.1, np.nan])
    return r


def test_fractional_detuning_and_json(tmp_path: Path) -> None:
    r = _result()
    assert np.allclose(r.fractional_detuning("ltr"), -np.array([300, 800, 1300]) / 8920.0)
    assert np.allclose(r.expected_fractional_detuning("rtl"), np.array([310, 810, 1310]) / 6630)
    paths = write_alpha_sweep(r, tmp_path)
    assert {p.name for p in paths} == {"alpha_sweep.png", "alpha_sweep.pdf", "alpha_sweep.json"}
    data = json.loads((tmp_path / "alpha_sweep.json").read_text())
    assert data["directions"]["rtl"]["transmission"][2] is None  # NaN -> null
    assert data["alphas"] == [0.1, 0.2, 0.3]
    text = format_alpha_sweep(r)
    assert len(text.splitlines()) == 1 + 6 and "-3.36" in text


def test_parse_amplitude() -> None:
    assert parse_amplitude("2um") == ("displacement", pytest.approx(2e-6))
    assert parse_amplitude("12 N") == ("force", 12.0)
    with pytest.raises(ValueError, match="displacement"):
        parse_amplitude("3 kHz")
    with pytest.raises(ValueError, match="displacement"):
        parse_amplitude("2")


def test_bad_sweep_inputs_refused_before_any_run() -> None:
    with pytest.raises(ValueError, match="alphas"):
        run_alpha_sweep([])
    with pytest.raises(ValueError, match="alphas"):
        run_alpha_sweep([-0.1])
    with pytest.raises(ValueError, match="duration"):
        run_alpha_sweep([0.1], duration_s=0.0)
