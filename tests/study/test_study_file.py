"""Study files: the cells they make, and bad ones refused in one line before any task."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from daq.cli.biafc import main
from protocols.study import cell_table, load_study, parse_study
from protocols.yamlfile import ConfigError

from .conftest import TINY


def test_grid_cells_are_every_design_point_at_every_amplitude(tiny_study: Path) -> None:
    table = cell_table(load_study(tiny_study).study)
    assert table.names == ("diameter", "preload", "n_cylinders", "amplitude")
    assert table.n_cells == 3 * 2 * 2
    np.testing.assert_allclose(np.unique(table.column("diameter")), [12e-3, 13.5e-3, 15e-3])
    np.testing.assert_allclose(table.values[:2, -1], [0.5e-6, 2e-6])  # amplitude inner
    assert list(table.point[:4]) == [0, 0, 1, 1]


def test_latin_hypercube_is_seeded_and_within_the_ranges() -> None:
    text = TINY.replace("sampling: grid", "sampling: {latin_hypercube: 20, seed: 3}")
    text = text.replace("{from: 12 mm, to: 15 mm, count: 3}", "{from: 12 mm, to: 15 mm}")
    text = text.replace("[3 N, 6 N]", "{from: 3 N, to: 6 N}")
    a = cell_table(parse_study(text).study)
    b = cell_table(parse_study(text).study)
    c = cell_table(parse_study(text.replace("seed: 3", "seed: 4")).study)
    assert a.n_cells == 40
    assert np.array_equal(a.values, b.values) and not np.array_equal(a.values, c.values)
    d = a.column("diameter")
    assert d.min() >= 12e-3 and d.max() <= 15e-3
    # one sample per stratum of each range
    strata = np.floor((np.unique(d) - 12e-3) / 3e-3 * 20).astype(int)
    assert sorted(strata) == list(range(20))


def test_the_digest_follows_what_decides_the_results(tiny_study: Path) -> None:
    sf = load_study(tiny_study)
    renamed = parse_study(TINY.replace("name: tiny", "name: other\ndescription: x"))
    changed = parse_study(TINY.replace("preload: [3 N, 6 N]", "preload: [3 N, 7 N]"))
    assert sf.digest("c") == renamed.digest("c")
    assert sf.digest("c") != changed.digest("c")
    assert sf.digest("c") != sf.digest("another chain")


BAD = [
    (
        "  diamter: {from: 12 mm, to: 15 mm, count: 3}",
        4,
        "parameters.diamter",
        "did you mean 'diameter'",
    ),
    (
        "  diameter: {from: 12 mm, to: 15 mm, count: 0}",
        4,
        "parameters.diameter.count",
        "empty range",
    ),
    ("  diameter: []", 4, "parameters.diameter", "empty range"),
    ("  diameter: {from: 15 mm, to: 12 mm, count: 3}", 4, "parameters.diameter.to", "empty range"),
    (
        "  diameter: {from: 12 N, to: 15 mm, count: 3}",
        4,
        "parameters.diameter.from",
        "is a force, expected a length",
    ),
    ("  diameter: {from: 12, to: 15 mm, count: 3}", 4, "parameters.diameter.from", "no unit"),
]


@pytest.mark.parametrize(("line", "lineno", "field", "why"), BAD)
def test_a_bad_study_is_refused_in_one_line_naming_file_line_and_field(
    tmp_path: Path, line: str, lineno: int, field: str, why: str, capsys: pytest.CaptureFixture[str]
) -> None:
    text = TINY.replace("  diameter: {from: 12 mm, to: 15 mm, count: 3}", line)
    p = tmp_path / "bad.yaml"
    p.write_text(text)
    out = tmp_path / "bad.h5"
    with pytest.raises(ConfigError):
        load_study(p)
    assert main(["study", str(p), "--workers", "2", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert f"{p}:{lineno}: {field}: " in err and why in err, err
    assert not out.exists()  # refused before any task


def test_wrong_amplitude_units_and_unknown_metric_are_refused(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"<study>:9: drive\.amplitudes: .*neither"):
        parse_study(TINY.replace("[0.5 um, 2 um]", "[0.5 um, 2 V]"))
    with pytest.raises(ConfigError, match=r"metrics: 'asymetry_ratio'.*did you mean"):
        parse_study(TINY + "metrics: [asymetry_ratio]\n")


def test_a_chain_no_cell_can_have_is_refused_before_any_task(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    chain = tmp_path / "dashpot.yaml"
    chain.write_text(
        "n_cylinders: 5\nlength_first: 90 mm\nlength_last: 110 mm\n"
        "damping: {bending_mode_ratio: 0.002, contact_dashpot_ratio: 0.005}\n"
    )
    p = tmp_path / "s.yaml"
    p.write_text(
        TINY.replace("sampling: grid", "chain: dashpot.yaml\nsampling: grid").replace(
            "  n_cylinders: 5", "  n_cylinders: 5\n  bending_mode_ratio: [0.002, 1.0]"
        )
    )
    out = tmp_path / "s.h5"
    assert main(["study", str(p), "--workers", "2", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert f"{p}:8: parameters.bending_mode_ratio: no chain for" in err, err
    assert "bending_mode_ratio = 1.0" in err
    assert not out.exists()


def test_a_preload_of_0_N_is_refused_with_the_range_before_any_task(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Before, 0 N was let through (docs/studies.md said it was refused) and every cell of it
    failed at run time."""
    p = tmp_path / "s.yaml"
    p.write_text(TINY.replace("[3 N, 6 N]", "[0 N, 6 N]"))
    out = tmp_path / "s.h5"
    assert main(["study", str(p), "--workers", "0", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert f"{p}:5: parameters.preload.0: '0 N' is outside (0, inf] N" in err, err
    assert not out.exists()


def test_damaged_results_are_refused_in_one_line(
    serial_reference: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Bytes flipped on disk inside a study's metrics: every per-cell dataset carries a
    Fletcher-32 checksum, so ``biafc figures`` refuses the file in one line (exit 2) where the
    flipped bytes read as results before."""
    import h5py

    from tests.engine.helpers import flip_bytes

    path = tmp_path / "damaged.h5"
    path.write_bytes(serial_reference.read_bytes())
    with h5py.File(path, "r") as f:
        info = f["metrics/asymmetry_ratio"].id.get_chunk_info(0)
    flip_bytes(path, info.byte_offset + 8)
    code = main(["figures", str(path), "--out", str(tmp_path / "figs")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and str(path) in err[0] and "damaged" in err[0], err
    assert not (tmp_path / "figs").exists()
    with h5py.File(serial_reference, "r") as f:
        assert all(f[name].fletcher32 for name in ("cells/status", "metrics/asymmetry_ratio"))


# a record or window that cannot hold the drive (before: every cell stored "ok" with the
# numbers of an aliased or cut-off signal); the checks are biafc simulate's
# (protocols.model_request), the window's against the longest burst the study plays
DRIVE_TOO_BIG = [
    (  # the paper's carriers above the Nyquist frequency of a 10 kS/s record
        (
            "simulation: {duration: 2 ms, rate: 100 kS/s}",
            "simulation: {duration: 15 ms, rate: 10 kS/s}",
        ),
        11,
        "simulation.rate",
        ("Nyquist frequency 5 kHz", "record at more than 28.06 kS/s"),
    ),
    (  # a carrier parameter: every value is checked, not only the first
        ("  n_cylinders: 5", "  n_cylinders: 5\n  carrier_ltr: [8.92 kHz, 150 kHz]"),
        7,
        "parameters.carrier_ltr",
        ("150 kHz burst", "Nyquist frequency 50 kHz"),
    ),
    (  # a Latin hypercube's carrier range: its top end
        ("  n_cylinders: 5", "  n_cylinders: 5\n  carrier_rtl: {from: 6 kHz, to: 60 kHz}"),
        7,
        "parameters.carrier_rtl",
        ("60 kHz burst", "Nyquist frequency 50 kHz"),
    ),
    (  # a 0.5 ms window against a 3.2 ms narrowband burst at 6.63 kHz
        ("burst: {cycles: 5}", "burst: {shape: narrowband}"),
        11,
        "simulation.duration",
        ("shorter than the 6.63 kHz burst (3.167 ms, 21 cycles)", "give at least 3.167 ms"),
    ),
    (  # the cycles parameter's largest value at the lowest carrier
        ("  n_cylinders: 5", "  n_cylinders: 5\n  cycles: [5, 20]"),
        12,
        "simulation.duration",
        ("shorter than the 6.63 kHz burst (3.017 ms, 20 cycles)",),
    ),
    (
        ("  n_cylinders: 5", "  n_cylinders: 5\n  cycles: [0.5, 5]"),
        7,
        "parameters.cycles",
        ("0.5 is outside 1 .. 1000",),
    ),
]


def _refused(tmp_path: Path, text: str, capsys: pytest.CaptureFixture[str]) -> tuple[Path, str]:
    """Run the study ``text`` (as ``tmp_path/s.yaml``): refused, exit 2, in one line, no output
    made. Returns the study file's path and that line."""
    p = tmp_path / "s.yaml"
    p.write_text(text)
    out = tmp_path / "s.h5"
    assert main(["study", str(p), "--workers", "0", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert not out.exists()
    return p, err


@pytest.mark.parametrize(("edit", "lineno", "field", "whys"), DRIVE_TOO_BIG)
def test_a_record_that_cannot_hold_the_drive_is_refused_before_any_task(
    tmp_path: Path,
    edit: tuple[str, str],
    lineno: int,
    field: str,
    whys: tuple[str, ...],
    capsys: pytest.CaptureFixture[str],
) -> None:
    text = TINY.replace(*edit)
    if "carrier_rtl: {" in text:
        text = text.replace("sampling: grid", "sampling: {latin_hypercube: 4, seed: 1}")
        text = text.replace("{from: 12 mm, to: 15 mm, count: 3}", "13 mm").replace(
            "[3 N, 6 N]", "5 N"
        )
    if "shape: narrowband" in text:
        text = text.replace("duration: 2 ms", "duration: 0.5 ms")
    assert text != TINY
    p, err = _refused(tmp_path, text, capsys)
    assert f"{p}:{lineno}: {field}: " in err, err
    for why in whys:
        assert why in err, err


def test_a_record_that_holds_every_burst_is_accepted() -> None:
    ok = TINY.replace("  n_cylinders: 5", "  n_cylinders: 5\n  carrier_ltr: [5 kHz, 30 kHz]")
    parse_study(ok)  # 30 kHz, 5 cycles: up to 47 kHz, below 50 kHz
    parse_study(TINY.replace("duration: 2 ms", "duration: 0.76 ms"))  # 5 cycles at 6.63 kHz


def test_a_cycles_parameter_needs_no_burst_given() -> None:
    """The default burst (a named shape) made a cycles parameter refused until a dummy
    ``burst: {cycles: 10}`` was added (a second reader); a shape named in the file still is."""
    text = TINY.replace("  burst: {cycles: 5}\n", "").replace(
        "  n_cylinders: 5", "  n_cylinders: 5\n  cycles: [5, 10]"
    )
    cells = cell_table(parse_study(text).study)
    column = cells.values[:, list(cells.names).index("cycles")]
    assert sorted(set(np.round(column, 6))) == [5.0, 10.0]
    named = text.replace("  amplitudes:", "  burst: {shape: narrowband}\n  amplitudes:")
    with pytest.raises(ConfigError, match="cycles is a parameter; drop the named shape"):
        parse_study(named)


LHS = """\
name: lhs
sampling: {latin_hypercube: 400, seed: 2}
parameters:
  diameter: {from: 12 mm, to: 15 mm}
  n_cylinders: {from: 5, to: 8}
drive:
  amplitudes: [1 um]
  burst: {cycles: 5}
simulation: {duration: 2 ms, rate: 100 kS/s}
"""


def test_a_latin_hypercube_draws_each_whole_number_in_equal_shares() -> None:
    """Rounding gave the two ends of 5..8 half a share each (6/14/13/7 of 40)."""
    cells = cell_table(parse_study(LHS).study)
    n = cells.values[:, list(cells.names).index("n_cylinders")]
    assert sorted(set(n)) == [5.0, 6.0, 7.0, 8.0]
    assert [int(np.count_nonzero(n == k)) for k in (5, 6, 7, 8)] == [100, 100, 100, 100]


@pytest.mark.parametrize(
    ("old", "new", "expect"),
    [
        ("latin_hypercube: 400", "latin_hypercube: 0", "sampling.latin_hypercube: give 1 to"),
        (
            "  diameter: {from: 12 mm, to: 15 mm}\n  n_cylinders: {from: 5, to: 8}",
            "  diameter: 12 mm",
            "a Latin hypercube needs a parameter given as a range",
        ),
    ],
)
def test_a_latin_hypercube_that_cannot_sample_is_refused_saying_why(
    old: str, new: str, expect: str
) -> None:
    with pytest.raises(ConfigError, match=expect):
        parse_study(LHS.replace(old, new))


def test_a_window_that_cannot_hold_the_transit_to_the_far_end_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A study checked its window against the burst only: 31 cylinders at 0.5 N need about
    0.96 ms for the burst to reach the far end, so a 1.2 ms window ran every cell, stored
    "ok", with a far end that nothing had reached yet. The cell that needs the longest window
    is named (here the slower chain and the longer, 6.63 kHz burst)."""
    text = (
        TINY.replace("  n_cylinders: 5", "  n_cylinders: 31")
        .replace("[3 N, 6 N]", "[0.5 N, 6 N]")
        .replace("duration: 2 ms", "duration: 1.2 ms")
    )
    p, err = _refused(tmp_path, text, capsys)
    assert f"{p}:11: simulation.duration: 1.2 ms cannot hold the rtl burst" in err, err
    assert "preload = 0.5 N" in err and "over 30 contacts" in err and "give at least" in err
    ok = tmp_path / "ok.yaml"
    ok.write_text(text.replace("duration: 1.2 ms", "duration: 2 ms"))
    assert main(["study", str(ok), "--dry-run", "--out", str(tmp_path / "s.h5")]) == 0


def test_the_transit_check_builds_no_chain_where_the_window_is_long_enough(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A reviewer: the check built every distinct chain (its modes): a 2000-sample Latin
    hypercube's dry run took 13.8 s, against 1 s before. A bound from the cylinders' whole
    masses decides first; a chain is built only where a window fails that bound."""
    import sim_backend.dem.chain
    from analysis.study_cells import StudySetup, check_transit
    from protocols.study import cell_table
    from sim_backend.dem.spec import default_chain_spec

    def no_build(spec: object) -> object:
        raise AssertionError("a chain was built")

    text = (
        TINY.replace("sampling: grid", "sampling: {latin_hypercube: 50, seed: 3}")
        .replace("{from: 12 mm, to: 15 mm, count: 3}", "{from: 12 mm, to: 15 mm}")
        .replace("[3 N, 6 N]", "{from: 3 N, to: 6 N}")
    )
    study = parse_study(text).study
    table = cell_table(study)
    setup = StudySetup(study, default_chain_spec().model_dump_json(), table.names)
    monkeypatch.setattr(sim_backend.dem.chain, "build_chain", no_build)
    assert check_transit(setup, table) is None


def test_the_transit_refusal_shows_a_latin_hypercubes_values_readably(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A second reader: the refusal printed raw floats ("diameter = 0.015337945819433435 m")."""
    import re

    text = (
        TINY.replace("sampling: grid", "sampling: {latin_hypercube: 6, seed: 2}")
        .replace("{from: 12 mm, to: 15 mm, count: 3}", "{from: 12 mm, to: 15 mm}")
        .replace("[3 N, 6 N]", "{from: 0.5 N, to: 1 N}")
        .replace("  n_cylinders: 5", "  n_cylinders: 31")
        .replace("duration: 2 ms", "duration: 1.2 ms")
    )
    p = tmp_path / "s.yaml"
    p.write_text(text)
    assert main(["study", str(p), "--dry-run", "--out", str(tmp_path / "s.h5")]) == 2
    err = capsys.readouterr().err
    assert re.search(r"diameter = 1\d\.?\d{0,2} mm, preload = 0\.\d{1,4} N,", err), err


def test_the_transit_check_builds_only_the_shortest_cylinder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """A second reader: a window failing the mass bound built the whole chain (every
    cylinder's modes) for one number, the lightest rigid mass: 2000 chains took 6.6 s. The
    shortest cylinder is the lightest, and its modes alone give the same crossing time."""
    import sim_backend.dem.chain as chain_module
    from sim_backend.dem.spec import default_chain_spec

    spec = default_chain_spec()
    for s in (  # slender cylinders, and Timoshenko disks, whose m0 is not monotonic in length
        spec,
        spec.model_copy(update={"length_first": 1.6e-3, "length_last": 2.0e-3}),
        spec.model_copy(update={"beam_theory": "euler-bernoulli", "n_modes": 2}),
    ):
        with np.errstate(all="ignore"):  # a disk's highest modes overflow cosh on the way
            full = chain_module.build_chain(s)
        exact = (float(full.m0_kg.min()) / full.K_lin) ** 0.5
        assert chain_module.crossing_time_s(s) == pytest.approx(exact, rel=1e-12)

    def no_build(spec: object) -> object:
        raise AssertionError("a whole chain was built")

    monkeypatch.setattr(chain_module, "build_chain", no_build)
    text = (
        TINY.replace("  n_cylinders: 5", "  n_cylinders: 31")
        .replace("[3 N, 6 N]", "[0.5 N, 6 N]")
        .replace("duration: 2 ms", "duration: 1.2 ms")
    )
    _, err = _refused(tmp_path, text, capsys)
    assert "over 30 contacts" in err and "give at least 1.78 ms" in err
