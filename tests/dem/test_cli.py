"""``biafc bands`` and ``biafc simulate``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from daq.cli.biafc import main
from protocols.runfile import read_run


def test_bands_table_and_csv(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "bands.csv"
    assert main(["bands", "--csv", str(out), "--bands", "2"]) == 0
    text = capsys.readouterr().out
    rows = [line.split() for line in text.splitlines() if not line.startswith("#")]
    assert rows[0][:2] == ["cylinder", "length_mm"]
    assert len(rows) == 32
    central = rows[16]
    assert central[0] == "16" and float(central[1]) == pytest.approx(100.0)
    assert float(central[4]) == pytest.approx(6.62, abs=0.02)  # band 1 onset, kHz
    assert float(central[5]) == pytest.approx(8.94, abs=0.03)  # band 1 cutoff, kHz
    lines = out.read_text().splitlines()
    assert len(lines) == 32 and lines[0].startswith("cylinder,length_mm,band0_onset_kHz")


def test_bands_bad_chain_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("n_cylinders: 3\nlength_first: 90\nlength_last: 110 mm\n")
    assert main(["bands", "--chain", str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "length_first" in err and str(bad) in err


def test_simulate_writes_a_run_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "run.h5"
    argv = ["simulate", "--direction", "rtl", "--amplitude", "2 um", "--duration", "5 ms",
            "--rate", "250 kS/s", "--out", str(out)]  # fmt: skip
    assert main(argv) == 0
    captured = capsys.readouterr()
    text = captured.out
    assert "model run 1/1: model run done" in captured.err  # daq.progress, piped: plain lines
    assert "transmitted energy ratio" in text and "far-end output peak f_out" in text
    assert text.count("peak") == 1  # one far-end peak, one definition
    run = read_run(out)
    assert run.status == "complete" and run.backend == "dem"
    scan = run.scans["rtl"]
    assert scan.velocity.shape == (1, 31, 1251)
    assert scan.amplitude_units == "m" and scan.amplitudes[0] == pytest.approx(2e-6)
    assert np.all(scan.done == 1)
    assert np.all(np.isfinite(scan.velocity))
    assert scan.f_center_Hz == pytest.approx(6.63e3)
    assert run.chain.onset_Hz.shape == (31, 3)
    assert run.simulation["integrator"] == "blanes-moan4"
    # refuses to overwrite; force drive accepted
    assert main(argv) == 2
    out2 = tmp_path / "force.h5"
    assert main(["simulate", "--direction", "ltr", "--amplitude", "3N", "--duration", "2 ms",
                 "--out", str(out2)]) == 0  # fmt: skip
    assert read_run(out2).scans["ltr"].amplitude_units == "N"


@pytest.mark.parametrize(
    ("extra", "word"),
    [
        (["--amplitude", "2"], "--amplitude"),
        (["--amplitude", "2 V"], "--amplitude"),
        (["--amplitude", "2 um", "--duration", "30"], "--duration"),
        (["--amplitude", "2 um", "--integrator", "euler"], "--integrator"),
    ],
)
def test_simulate_bad_input(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], extra: list[str], word: str
) -> None:
    out = tmp_path / "x.h5"
    assert main(["simulate", "--direction", "ltr", "--out", str(out), *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and word in err
    assert not out.exists()


def test_bands_check_against_continuum(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bands", "--check", "--bands", "2"]) == 0
    lines = [x for x in capsys.readouterr().out.splitlines() if x.startswith("# band 1")]
    assert len(lines) == 1
    cutoff_pct = float(lines[0].split("cutoff")[1].split("%")[0])
    assert 0 <= cutoff_pct < 1.0


def test_far_end_peak_is_the_same_in_simulate_and_figures(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """One definition of the far-end peak: ``biafc simulate`` prints the value ``biafc figures``
    puts in the summary (they printed 1.8 kHz and 7.9 kHz for one run), and names what it is;
    the energy line says what it measures (work not in the chain, dissipated: not a residual)."""
    import json
    import re

    out = tmp_path / "run.h5"
    argv = ["simulate", "--direction", "ltr", "--amplitude", "4um", "--duration", "10 ms",
            "--rate", "250 kS/s", "--out", str(out)]  # fmt: skip
    assert main(argv) == 0
    text = capsys.readouterr().out
    m = re.search(r"far-end output peak f_out \(largest line of cylinder 31's velocity spectrum "
                  r"in [0-9.]+-[0-9.]+ kHz.*\): ([0-9.]+) kHz", text)  # fmt: skip
    assert m, text
    assert "input work not in the chain at the end" in text and "dissipated" in text
    assert "residual" not in text
    assert main(["figures", str(out), "--out", str(tmp_path / "fig")]) == 0
    figures_text = capsys.readouterr().out
    assert "f_out: far-end output peak" in figures_text
    row = json.loads((tmp_path / "fig" / "summary.json").read_text())["rows"][0]
    assert float(m.group(1)) == pytest.approx(row["output_Hz"] / 1e3, abs=5e-4)


def test_simulate_honours_a_stable_step_finer_than_a_sample(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``--dt '1 us'`` runs at 1 us; coarser steps are refused (tests/bad_inputs, issue 16)."""
    out = tmp_path / "fine.h5"
    argv = ["simulate", "--direction", "ltr", "--amplitude", "1 um", "--duration", "1 ms",
            "--dt", "1 us", "--no-error-estimate", "--out", str(out)]  # fmt: skip
    assert main(argv) == 0
    assert read_run(out).simulation["dt_s"] == pytest.approx(1e-6)
