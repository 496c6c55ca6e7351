"""The analysis window and the analytic signal without ``scipy.signal``, whose import took
0.7-1.1 s of every ``biafc figures`` (issue 18, no hidden seconds): the same numbers as scipy's,
and a figure command's modules no longer import it."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import hilbert, windows

from analysis.envelope import analytic_signal
from analysis.spectra import TUKEY_ALPHA, tukey, window_for
from tests.fresh_process import python_c


@pytest.mark.parametrize("n", [0, 1, 2, 3, 4, 10, 101, 1000, 13000])
@pytest.mark.parametrize("alpha", [-0.5, 0.0, 0.01, TUKEY_ALPHA, 0.5, 0.99, 1.0, 1.5])
def test_tukey_is_scipys_symmetric_tukey(n: int, alpha: float) -> None:
    ours = tukey(n, alpha)
    theirs = windows.tukey(n, alpha, sym=True)
    assert ours.dtype == np.float64 and ours.shape == (n,)
    np.testing.assert_array_equal(ours, theirs)


def test_the_analysis_window_is_flat_over_its_middle() -> None:
    w = window_for(1000)
    assert w[0] == 0.0 and w[-1] == 0.0
    assert np.all(w[50:950] == 1.0)


@pytest.mark.parametrize("shape", [(1,), (2,), (7,), (64,), (3, 101), (2, 3, 128)])
def test_analytic_signal_is_scipys_hilbert(shape: tuple[int, ...]) -> None:
    x = np.random.default_rng(sum(shape)).normal(size=shape)
    ours = analytic_signal(x)
    theirs = hilbert(x, axis=-1)
    assert ours.shape == x.shape and ours.dtype == np.complex128
    np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-13 * np.abs(x).max())
    np.testing.assert_allclose(ours.real, x, rtol=0, atol=1e-13 * np.abs(x).max())


def test_analytic_signal_of_a_cosine_is_the_complex_tone() -> None:
    n = 1000
    t = np.arange(n)
    z = analytic_signal(np.cos(2 * np.pi * 50 * t / n))  # a whole number of periods
    np.testing.assert_allclose(z, np.exp(2j * np.pi * 50 * t / n), atol=1e-12)


def test_an_empty_record_is_refused() -> None:
    with pytest.raises(ValueError, match="empty"):
        analytic_signal(np.zeros(0))


def test_the_figure_commands_and_the_windows_modules_import_no_scipy_signal() -> None:
    """``biafc figures``' modules (the report, the spectra, the envelopes, the bench's preflight
    checks) and the bench window's (with the model overlay, which brings the linear response)
    in a fresh process: no ``scipy.signal`` (it was imported by the spectra's window, the
    envelopes' Hilbert transform and the linear response's module; this test failed then)."""
    code = (
        "import sys\n"
        "import analysis.report, analysis.spectra, analysis.envelope, daq.preflight\n"
        "import analysis.model_overlay, daq.gui.main_window\n"
        "print(sorted(m for m in sys.modules if m.startswith('scipy.signal')))\n"
    )
    out = python_c(code)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]", out.stdout
