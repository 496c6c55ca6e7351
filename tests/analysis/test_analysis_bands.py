"""Band edges read from a run's /chain and what they predict."""

from __future__ import annotations

import dataclasses

import analysis_synthetic as synthetic
import numpy as np
import pytest

from analysis.bands import (
    asymmetry_factor,
    band_edges,
    entry_cylinder,
    expected_output_Hz,
    far_cylinder,
    linear_limit_cylinder,
    peak_search_range_Hz,
    resonance_band_index,
)


def test_resonance_band_found_with_and_without_the_acoustic_band() -> None:
    ch = synthetic.chain()
    assert resonance_band_index(ch) == 1
    only_lr = dataclasses.replace(ch, onset_Hz=ch.onset_Hz[:, 1:], cutoff_Hz=ch.cutoff_Hz[:, 1:])
    assert resonance_band_index(only_lr) == 0
    o1, c1 = band_edges(ch)
    o2, c2 = band_edges(only_lr)
    assert np.array_equal(o1, o2) and np.array_equal(c1, c2)
    with pytest.raises(ValueError, match="no local-resonance band"):
        resonance_band_index(dataclasses.replace(ch, onset_Hz=np.zeros((31, 1))))


def test_ends_and_expected_outputs() -> None:
    onset, cutoff = band_edges(synthetic.chain())
    assert (entry_cylinder("ltr", 31), far_cylinder("ltr", 31)) == (1, 31)
    assert (entry_cylinder("rtl", 31), far_cylinder("rtl", 31)) == (31, 1)
    # LTR 8.92 kHz lies above the 110 mm cylinder's band: down to its cutoff
    assert expected_output_Hz(8920.0, "ltr", onset, cutoff) == pytest.approx(8010.0)
    # RTL 6.63 kHz lies below the 90 mm cylinder's band: up to its onset
    assert expected_output_Hz(6630.0, "rtl", onset, cutoff) == pytest.approx(8080.0)
    assert expected_output_Hz(9000.0, "rtl", onset, cutoff) == 9000.0
    with pytest.raises(ValueError, match="direction"):
        far_cylinder("up", 31)


def test_linear_limit_is_where_the_input_leaves_the_band() -> None:
    onset, cutoff = band_edges(synthetic.chain())
    lim = linear_limit_cylinder(8920.0, "ltr", onset, cutoff)
    assert lim is not None
    assert cutoff[lim - 1] < 8920.0 <= cutoff[lim - 2]
    lim_r = linear_limit_cylinder(6630.0, "rtl", onset, cutoff)
    assert lim_r is not None
    assert onset[lim_r - 1] > 6630.0 >= onset[lim_r]
    assert linear_limit_cylinder(8050.0, "ltr", np.full(5, 7e3), np.full(5, 9e3)) is None


def test_asymmetry_factor_of_a_linear_profile() -> None:
    onset, cutoff = band_edges(synthetic.chain())
    a_c = (10000 - 8010) / ((10000 + 8010) / 2)
    a_s = (8080 - 5400) / ((8080 + 5400) / 2)
    assert asymmetry_factor(onset, cutoff) == pytest.approx((a_c + a_s) / 2)
    assert asymmetry_factor(np.full(31, 7e3), np.full(31, 9e3)) == 0.0


def test_peak_search_range_brackets_the_band() -> None:
    onset, cutoff = band_edges(synthetic.chain())
    lo, hi = peak_search_range_Hz(6630.0, onset, cutoff)
    assert lo < onset.min() and hi > cutoff.max()
    assert lo > 1000.0
