"""Chain files: the default, bad input (one line naming the field), the alpha construction."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from sim_backend import dem
from sim_backend.dem.alpha import asymmetry_factor

GOOD = """\
n_cylinders: 5
length_first: 90 mm
length_last: 110 mm
diameter: 13.6 mm
preload: 5 N
"""


def _write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "chain.yaml"
    p.write_text(text, encoding="utf-8")
    return p


def test_default_chain_spec() -> None:
    spec = dem.default_chain_spec()
    lengths = spec.lengths_m()
    assert lengths.size == 31
    assert lengths[0] == pytest.approx(0.09) and lengths[-1] == pytest.approx(0.11)
    assert spec.diameter == pytest.approx(13.6e-3)
    assert spec.preload == 5.0 and spec.n_modes == 3 and spec.far_end == "wall"


def test_good_file_and_round_trip(tmp_path: Path) -> None:
    spec = dem.load_chain_spec(_write(tmp_path, GOOD))
    assert spec.n == 5
    again = dem.load_chain_spec(_write(tmp_path, spec.to_yaml()))
    np.testing.assert_allclose(again.lengths_m(), spec.lengths_m(), rtol=1e-9)
    assert again.diameter == pytest.approx(spec.diameter)


@pytest.mark.parametrize(
    ("text", "field"),
    [
        (GOOD.replace("length_first: 90 mm", "length_first: -90 mm"), "length_first"),
        (GOOD + "colour: blue\n", "colour"),
        (GOOD.replace("preload: 5 N", "preload: 5"), "preload"),
        (GOOD.replace("diameter: 13.6 mm", "diameter: 13.6 N"), "diameter"),
        (GOOD + "material: {density: 2200}\n", "material.density"),
        ("lengths: [90 mm, -1 mm]\n", "lengths"),
        (GOOD + "lengths: [90 mm, 91 mm]\n", "lengths"),
        (GOOD + "damping: {resonator_ratio: -0.1}\n", "damping.resonator_ratio"),
        ("[1, 2]\n", "mapping"),
        (GOOD + "crossing_angle: 5 deg\n", "crossing_angle"),
        (GOOD + "crossing_angle: 90\n", "crossing_angle"),
    ],
)
def test_bad_files_give_one_line_naming_the_field(tmp_path: Path, text: str, field: str) -> None:
    path = _write(tmp_path, text)
    with pytest.raises(dem.ChainFileError) as info:
        dem.load_chain_spec(path)
    msg = str(info.value)
    assert "\n" not in msg
    assert str(path) in msg
    assert field in msg


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(dem.ChainFileError, match="cannot read"):
        dem.load_chain_spec(tmp_path / "nope.yaml")


def test_alpha_construction_hits_alpha_and_keeps_the_centre() -> None:
    base = dem.default_chain_spec()
    spec = dem.chain_spec_for_alpha(0.15, base)
    lengths = spec.lengths_m()
    assert lengths[15] == pytest.approx(0.1, rel=1e-12)
    assert np.all(np.diff(lengths) > 0)
    bands = dem.quasi_bands(dem.build_chain(spec), 2)
    assert asymmetry_factor(bands) == pytest.approx(0.15, rel=1e-6)
    # the onset edge is linear in cylinder number
    on = bands.onset_Hz[:, 1]
    fit = np.polyval(np.polyfit(np.arange(31), on, 1), np.arange(31))
    np.testing.assert_allclose(on, fit, rtol=1e-6)
    flat = dem.chain_spec_for_alpha(0.0, base).lengths_m()
    np.testing.assert_allclose(flat, 0.1)


@pytest.mark.parametrize("alpha", [-0.1, float("nan"), 50.0])
def test_impossible_alpha(alpha: float) -> None:
    with pytest.raises(dem.ChainFileError) as info:
        dem.chain_spec_for_alpha(alpha)
    assert str(info.value).startswith("alpha:")
    assert "\n" not in str(info.value)


def test_crossing_angle_round_trips(tmp_path: Path) -> None:
    spec = dem.load_chain_spec(_write(tmp_path, GOOD + "crossing_angle: 60 deg\n"))
    assert spec.crossing_angle == pytest.approx(math.radians(60.0))
    again = dem.load_chain_spec(_write(tmp_path, spec.to_yaml()))
    assert again.crossing_angle == pytest.approx(spec.crossing_angle)
    assert "crossing_angle" not in dem.default_chain_spec().to_yaml()
