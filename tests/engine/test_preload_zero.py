"""A chain without preload (``--set preload=0N``, the "sonic vacuum" the chain file allows):
the model's commands work on it (the dry run, bands, simulate with --explain and --lean,
regime), and the figures that need a local-resonance band say in one line that it has none.
Before, ``run_protocol --dry-run`` ended in a ZeroDivisionError (the transit bound divides by
the linear contact stiffness, 0 here), ``biafc simulate`` and ``biafc regime`` wrote their file
and then a ValueError (no local-resonance band to search the output peak in), ``--explain``
divided by delta0 = 0, and ``biafc bands`` printed NaN cutoffs with numpy's warning (a cutoff
of 0 came out of round-off as sqrt(-1e-9))."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from daq.cli import run_protocol as rp
from daq.cli.biafc import main as biafc
from sim_backend import dem


def test_the_bands_of_a_chain_without_preload_are_finite() -> None:
    chain = dem.build_chain(dem.load_chain_with_settings(None, ["preload=0N"]))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        bands = dem.quasi_bands(chain, 3)
    assert np.all(np.isfinite(bands.onset_Hz)) and np.all(np.isfinite(bands.cutoff_Hz))
    assert np.all(bands.cutoff_Hz[:, 0] < 1e-2)  # no acoustic band without a contact stiffness


def test_a_dry_run_without_preload_plans_the_run(capsys: pytest.CaptureFixture[str]) -> None:
    assert rp.main(["smoke", "--set", "preload=0N", "--dry-run"]) == 0
    assert "6 points" in capsys.readouterr().out


def test_simulate_without_preload_writes_its_file_and_summary(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "sv.h5"
    args = ["simulate", "--direction", "ltr", "--amplitude", "1um", "--set", "preload=0N"]
    assert biafc([*args, "--duration", "5ms", "--rate", "200kS/s", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "transmitted energy ratio" in text and "far-end output peak f_out" in text
    assert "in 4.46-13.38 kHz, half to one and a half times the input: the chain has no" in text
    # --explain and --lean: the scene's overlap ratio divided by delta0 = 0
    assert biafc([*args, "--explain"]) == 0
    assert "overlap change inf delta0" in capsys.readouterr().out
    figs = tmp_path / "figs"
    assert biafc(["figures", str(out), "--out", str(figs)]) == 2  # no band: said, one line
    err = capsys.readouterr().err.strip()
    assert "no local-resonance band" in err and len(err.splitlines()) == 1
    assert out.exists()
