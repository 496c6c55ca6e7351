"""``biafc calibrate``: the fit recovers a chain it is not told, and refuses what it cannot fit."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from analysis.calibrate import CalibrationError, calibrate, parse_fit
from analysis.model_run import with_resonator_damping
from analysis.synthetic_scan import write_synthetic_scan
from daq.cli.biafc import main as biafc
from daq.cli.run_protocol import main as run_protocol
from protocols.bench import default_bench_path
from protocols.runfile import read_run
from sim_backend.dem import build_chain, default_chain_spec, load_chain_spec

BASE = default_chain_spec()
#: the truth the fit is not told: F0 4.3 N, d 13.9 mm, resonators' Q 100 (default 250), stroke x0.8
TRUE = with_resonator_damping(BASE.model_copy(update={"preload": 4.3, "diameter": 13.9e-3}), 0.005)
TRUE_VALUES = {"F0": 4.3, "diameter": 13.9e-3, "damping": 0.005, "stroke": 0.8 * 5e-8}
TOLERANCE = {"F0": 0.02, "diameter": 0.02, "damping": 0.15, "stroke": 0.03}


@pytest.fixture(scope="module")
def measured(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Every third cylinder, one linear and one nonlinear amplitude, noise and trigger jitter."""
    path = tmp_path_factory.mktemp("cal") / "measured.h5"
    return write_synthetic_scan(
        path,
        true_spec=TRUE,
        stroke_factor=0.8,
        amplitudes_m=(30e-9, 3e-6),
        cylinders=tuple(range(1, 32, 3)),
        duration_s=8e-3,
        noise_m_per_s=2e-6,
        jitter_s=2e-6,
        seed=3,
        failed=[("rtl", 0, 4)],
    )


def test_fit_recovers_the_withheld_chain_from_the_defaults(measured: Path) -> None:
    # the linear stage, then the DEM stage on every point (linear and nonlinear)
    res = calibrate(read_run(measured), nonlinear=True, max_dem_evaluations=15)
    assert res.dem_stage["points"] == 2 * 2 * 11 - 1
    assert res.dem_stage["after"] <= res.dem_stage["before"] < 0.05
    assert res.start["F0"] == 5.0 and res.start["diameter"] == pytest.approx(13.6e-3)
    for name, true in TRUE_VALUES.items():
        err = abs(res.values[name] / true - 1.0)
        assert err < TOLERANCE[name], f"{name}: {res.values[name]:.6g} against {true:.6g}"
        assert 0 < res.std[name] < 0.05 * true
    assert res.residual_after < 0.1 * res.residual_before
    # the correlation matrix: unit diagonal, symmetric, every entry a correlation
    c = res.correlation
    assert np.allclose(np.diag(c), 1.0) and np.allclose(c, c.T) and np.all(np.abs(c) <= 1 + 1e-9)
    assert res.n_points == 2 * 11 - 1  # the linear amplitude, one point failed
    assert any("nonlinear points left out of the linear fit" in n for n in res.notes)
    # the table says what its +/- are: on the simulated bench the stroke came out 22 sigma off
    # the truth (0.23 %), the model's own error, with nothing printed to say so
    assert "the +/- are statistical" in res.table() and "biafc compare" in res.table()


def test_only_the_named_parameters_move(measured: Path) -> None:
    res = calibrate(read_run(measured), ("stroke",))
    assert res.names == ("stroke",)
    assert res.spec.preload == BASE.preload and res.spec.diameter == BASE.diameter
    assert res.correlation.shape == (1, 1)


def test_too_few_cylinders_is_refused_saying_what_the_fit_needs(tmp_path: Path) -> None:
    path = write_synthetic_scan(
        tmp_path / "three.h5", true_spec=BASE, amplitudes_m=(30e-9,), cylinders=(1, 16, 31),
        duration_s=6e-3,
    )  # fmt: skip
    with pytest.raises(CalibrationError, match=r"3 cylinder\(s\).*at least 5 cylinders"):
        calibrate(read_run(path))


def test_only_saturated_points_are_refused(tmp_path: Path) -> None:
    # a sensitive range (5 mm/s/V: clips at 50 mm/s) and amplitudes of microns only
    path = write_synthetic_scan(
        tmp_path / "loud.h5", true_spec=BASE, amplitudes_m=(2e-6, 5e-6), cylinders=(1, 8, 16),
        duration_s=6e-3, sensitivity_m_per_s_per_V=0.005,
    )  # fmt: skip
    with pytest.raises(CalibrationError, match="no linear point") as info:
        calibrate(read_run(path))
    msg = str(info.value)
    assert "clipped" in msg and "delta0" in msg and "tens of nm" in msg


def test_parse_fit_names_and_refuses_unknown() -> None:
    assert parse_fit("F0, damping,diameter,stroke") == ("F0", "damping", "diameter", "stroke")
    assert parse_fit("preload,E") == ("F0", "E")
    with pytest.raises(CalibrationError, match="unknown parameter 'mass'"):
        parse_fit("F0,mass")


def test_cli_writes_a_chain_file_every_command_accepts(
    measured: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "fitted_chain.yaml"
    rc = biafc(["calibrate", str(measured), "--fit", "F0,stroke", "--out", str(out), "--no-check"])
    text = capsys.readouterr().out
    assert rc == 0, text
    assert "correlations:" in text and "before" in text and "--piezo-stroke" in text
    assert "# stroke:" in out.read_text()
    spec = load_chain_spec(out)
    assert spec.preload != 5.0 and spec.diameter == BASE.diameter and build_chain(spec).n == 31
    summary = json.loads(out.with_suffix(".json").read_text())
    assert set(summary["parameters"]) == {"F0", "stroke"}
    # biafc bands, biafc simulate, the simulated bench and biafc compare take it as it is
    assert biafc(["bands", "--chain", str(out)]) == 0
    sim = ["--direction", "ltr", "--amplitude", "0.1um", "--duration", "2ms"]
    assert biafc(["simulate", "--chain", str(out), *sim, "--out", str(tmp_path / "s.h5")]) == 0
    bench = tmp_path / "bench.yaml"
    text = default_bench_path().read_text()
    bench.write_text(text.replace("chain: null", f"chain: {out.name}", 1))
    assert run_protocol(["smoke.yaml", "--bench", str(bench), "--out", str(tmp_path / "b.h5")]) == 0
    assert read_run(tmp_path / "b.h5").chain.f0_N == pytest.approx(spec.preload)
    stroke = summary["parameters"]["stroke"]["value"]
    cmp_dir = tmp_path / "cmp"
    stroke_arg = f"{stroke * 1e6:.6g} um/V"
    args = ["--chain", str(out), "--linear", "--piezo-stroke", stroke_arg, "--out", str(cmp_dir)]
    assert biafc(["compare", str(measured), *args]) == 0
    assert (cmp_dir / "comparison.json").exists()


@pytest.mark.parametrize("existing", [".yaml", ".json"])
def test_cli_does_not_overwrite_a_chain_file(
    measured: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], existing: str
) -> None:
    """A hand-made chain file (or the summary beside it) named by --out is left as it was."""
    out = tmp_path / "my_chain.yaml"
    kept = out.with_suffix(existing)
    kept.write_text("# my own chain\n")
    rc = biafc(["calibrate", str(measured), "--fit", "F0", "--out", str(out), "--no-check"])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1, err
    assert f"{kept} exists already" in err and "my_chain_2.yaml" in err
    assert kept.read_text() == "# my own chain\n"
    # the name offered is free with its .json too, and a chain file's (a reviewer: .h5)
    (tmp_path / "my_chain_2.json").write_text("{}")
    bare = tmp_path / "chainout"
    bare.write_text("x")
    assert biafc(["calibrate", str(measured), "--fit", "F0", "--out", str(out), "--no-check"]) == 2
    assert "--out " + str(tmp_path / "my_chain_3.yaml") in capsys.readouterr().err
    assert biafc(["calibrate", str(measured), "--fit", "F0", "--out", str(bare), "--no-check"]) == 2
    assert "chainout_2.yaml" in capsys.readouterr().err


def test_cli_refusal_is_one_line_with_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = write_synthetic_scan(
        tmp_path / "two.h5", true_spec=BASE, amplitudes_m=(30e-9,), cylinders=(1, 31),
        duration_s=6e-3,
    )  # fmt: skip
    assert biafc(["calibrate", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "at least 5 cylinders" in err


def test_calibrates_count_of_compared_points_leaves_out_the_noise_floor(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """A second reader: calibrate said "all 62 compared points" where biafc compare, on the
    same file and chain, said "61 compared, 1 far record at the noise floor"."""
    import math
    from types import SimpleNamespace

    import analysis.compare_report
    from daq.cli import calibrate as cli

    cmp = SimpleNamespace(
        counts={"ok": 62}, n_noise_floor=1, figure_of_merit=0.3, time_figure=0.4,
        noise_figure=0.39, spectral_noise_figure=0.27,
    )  # fmt: skip
    monkeypatch.setattr(
        analysis.compare_report, "compare_run",
        lambda *a, **k: SimpleNamespace(comparison=cmp),
    )  # fmt: skip
    result = SimpleNamespace(spec=None, names=(), stroke_m_per_V=math.nan)
    cli._check(None, None, result, None)
    out = capsys.readouterr().out
    assert "DEM prediction of 61 compared points" in out and "1 far record at the noise" in out
    assert "noise alone 0.270" in out


def test_the_fit_says_what_it_fits_each_stage_and_how_it_goes(measured: Path) -> None:
    """A fit said nothing until its table: 8.6 s on a linear_lowamp run (11 s with
    --nonlinear). It says now what it fits to how many points and residuals, each stage, and
    within a stage (every progress_every_s; here every evaluation) the evaluations so far and
    the relative residual."""
    lines: list[str] = []
    res = calibrate(read_run(measured), ("F0", "stroke"), progress=lines.append, progress_every_s=0)
    assert lines[0].startswith(
        f"fitting F0, stroke to {res.n_points} linear points ({res.n_residuals} residuals), "
        "relative residual "
    )
    assert lines[1].startswith("stage 1 of 2: linear-response model, spectra smoothed")
    assert sum(line.startswith("stage 2 of 2: ") for line in lines) == 1
    ticks = [line for line in lines if line.startswith("  stage ")]
    assert ticks[0].startswith("  stage 1: 1 evaluations, relative residual 0.")
    assert len(ticks) == res.n_evaluations - 1  # all but the one at the start values


def test_cli_says_the_fit_on_stderr_and_the_compare_after_figures(
    measured: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """--figures wrote a compare_after/ folder (biafc compare's figures, residuals.csv and
    comparison.json: 6 figures on a linear_lowamp run) that the output never mentioned; each is
    said now as it is written. The fit's progress goes to stderr; -q silences it."""
    figs = tmp_path / "figs"
    out = tmp_path / "c.yaml"
    assert biafc(["calibrate", str(measured), "--fit", "F0", "--out", str(out),
                  "--figures", str(figs)]) == 0  # fmt: skip
    cap = capsys.readouterr()
    assert cap.err.startswith("fitting F0 to ") and "stage 2 of 2" in cap.err
    assert "predicting every point with the DEM" in cap.err
    after = figs / "compare_after"
    pngs = sorted(after.glob("*.png"))
    assert len(pngs) == 8  # two amplitudes: low and high maps per direction
    for png in pngs:
        assert f"written {png.stem}: {png}, {png.with_suffix('.pdf')}" in cap.out
    assert f"written {after / 'comparison.json'}" in cap.out
    assert cap.out.index("DEM prediction of") < cap.out.index(f"written {pngs[0].stem}:")
    out2 = tmp_path / "q.yaml"
    assert biafc(["calibrate", str(measured), "--fit", "F0", "--out", str(out2), "-q",
                  "--no-check"]) == 0  # fmt: skip
    cap = capsys.readouterr()
    assert cap.err == "" and "relative spectral residual" in cap.out
