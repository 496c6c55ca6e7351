"""The far end always has a largest line: ``biafc simulate`` and the regime figure say whether
it is a conversion (the verdict of :func:`analysis.summary.conversion_verdict`), not only where
it lies."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from analysis.summary import summary_rows, verdict_reason
from analysis.sweep import amplitude_sweep
from analysis.synthetic_scan import write_synthetic_scan
from daq.cli.biafc import main
from protocols.runfile import read_run
from sim_backend.dem import default_chain_spec


def _f_out_line(text: str) -> str:
    (line,) = [ln for ln in text.splitlines() if "far-end output peak f_out" in ln]
    return line


def test_simulate_says_a_linear_leaks_line_is_not_a_conversion(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """RTL at 10 nm printed "f_out 8.002 kHz, detuning +1.372 kHz" for E_far/E_in 7.1e-8, as
    if it had converted."""
    common = ["--duration", "10 ms", "--rate", "250 kS/s"]
    out = tmp_path / "small.h5"
    argv = ["simulate", "--direction", "rtl", "--amplitude", "0.01um", *common]
    assert main([*argv, "--out", str(out)]) == 0
    line = _f_out_line(capsys.readouterr().out)
    assert "not converted by the one-amplitude rule: E_far/E_in" in line and "below 0.01" in line
    assert "biafc regime" in line  # one run cannot tell, and it says what can
    big = tmp_path / "big.h5"
    argv = ["simulate", "--direction", "ltr", "--amplitude", "2um", *common]
    assert main([*argv, "--out", str(big)]) == 0
    text = capsys.readouterr().out
    # a reviewer: one run never says "converted" (a 2-cycle burst's linear leak passes the
    # level at 1 nm as at 10 nm): it says what the one-amplitude rule gives
    line = _f_out_line(text)
    assert "down by the one-amplitude rule (E_far/E_in" in line and "converted down" not in line
    assert "cannot tell a conversion from a linear leak" in line
    assert text.count("peak") == 1  # still one far-end peak, one definition


def test_verdict_reason_with_a_linear_reference() -> None:
    row = {"conversion": "none", "transmission": 1e-4, "transmission_gain": 1.2,
           "input_Hz": 6630.0, "detuning_Hz": 1372.0, "at_noise_floor": False}  # fmt: skip
    assert verdict_reason(row) == "not converted: gain 1.2 over the linear reference, below 3"
    row |= {"conversion": "up", "transmission_gain": 40.0}
    assert verdict_reason(row).startswith("converted up: gain 40 over the linear reference >= 3")
    row |= {"conversion": "none", "detuning_Hz": 50.0}
    assert verdict_reason(row) == "not converted: |detuning| 0.8% of f_in, below 2%"
    assert "noise floor" in verdict_reason(row | {"at_noise_floor": True})


def test_the_regime_figure_draws_lines_that_did_not_convert_hollow(tmp_path: Path) -> None:
    """The regime figure drew every far-end line as the converted ones are."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from analysis.plots.regime_plot import plot_regime

    path = write_synthetic_scan(
        tmp_path / "sweep.h5",
        true_spec=default_chain_spec(),
        amplitudes_m=(10e-9, 3e-6),
        cylinders=(1, 31),
        cycles=21.0,  # the narrowband default: sigma = 3.5 carrier periods
        duration_s=12e-3,
        noise_m_per_s=1e-9,
    )
    run = read_run(path)
    sweeps = {d: amplitude_sweep(s, run.chain) for d, s in run.scans.items()}
    fig = plot_regime(sweeps)
    ax_f = fig.axes[1]
    for d, sw in sweeps.items():
        verdicts = [r["conversion"] for r in summary_rows(sw)]
        assert verdicts[0] == "none" and verdicts[1] in ("down", "up")
        assert np.all(np.isfinite(sw.output_Hz))  # both have a largest line
        named = {str(ln.get_label()): ln for ln in ax_f.lines}
        hollow = named[f"{d.upper()} largest far-end line, not converted"]
        full = named[f"{d.upper()} far-end peak, converted"]
        assert hollow.get_markerfacecolor() == "none"
        assert np.allclose(hollow.get_xdata(), [0.01])  # um
        assert np.allclose(full.get_xdata(), [3.0])
    plt.close(fig)


def test_an_undetermined_line_is_drawn_apart_from_the_not_converted(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A reviewer: an "undetermined" point (the run cannot tell) was drawn with the lines that
    did not convert."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    import analysis.plots.regime_plot as regime_plot

    path = write_synthetic_scan(
        tmp_path / "sweep.h5", true_spec=default_chain_spec(), amplitudes_m=(10e-9, 3e-6),
        cylinders=(1, 31), cycles=21.0, duration_s=12e-3, noise_m_per_s=1e-9,
    )  # fmt: skip
    run = read_run(path)
    sweeps = {"ltr": amplitude_sweep(run.scans["ltr"], run.chain)}
    real = regime_plot.summary_rows

    def undetermined_first(sw: object, scan: object = None) -> list[dict[str, object]]:
        rows = real(sw)  # type: ignore[arg-type]
        return [{**rows[0], "conversion": "undetermined"}, *rows[1:]]

    monkeypatch.setattr(regime_plot, "summary_rows", undetermined_first)
    fig = regime_plot.plot_regime(sweeps)
    named = {str(ln.get_label()): ln for ln in fig.axes[1].lines}
    unsure = named["LTR far-end peak, undetermined"]
    assert np.allclose(unsure.get_xdata(), [0.01]) and unsure.get_markerfacecolor() == "none"
    assert "LTR largest far-end line, not converted" not in named
    plt.close(fig)
