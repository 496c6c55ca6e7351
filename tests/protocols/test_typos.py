"""A misspelt key, nested or not, in a protocol or bench file: the line names the unknown key
and the closest allowed one (not the field it left missing)."""

from __future__ import annotations

from pathlib import Path

import pytest

from daq.cli import run_protocol as rp
from protocols.bench import load_bench, parse_bench
from protocols.schema import parse_protocol
from protocols.yamlfile import ConfigError

PROTOCOL = """\
name: t
directions: [ltr]
burst:
  ltr: {f_center: 8.92 kHz, cycles: 5}
amplitudes: [1 um, 2 um]
cylinders: [1, 31]
acquisition:
  rate: 200 kS/s
  duration: 10 ms
"""


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        (
            "f_center: 8.92 kHz",
            "frequncy: 8.92 kHz",
            "p.yaml:4: burst.ltr.frequncy: unknown key 'frequncy'; did you mean 'f_center'?",
        ),
        (
            "cycles: 5",
            "cycels: 5",
            "p.yaml:4: burst.ltr.cycels: unknown key 'cycels'; did you mean 'cycles'?",
        ),
        (
            "  duration: 10 ms",
            "  duraton: 10 ms",
            "p.yaml:9: acquisition.duraton: unknown key 'duraton'; did you mean 'duration'?",
        ),
        (
            "[1 um, 2 um]",
            "{start: 1 um, stopp: 2 um, count: 3}",
            "p.yaml:5: amplitudes.stopp: unknown key 'stopp'; did you mean 'stop'?",
        ),
        (
            "cylinders:",
            "cylindres:",
            "p.yaml:6: cylindres: unknown key 'cylindres'; did you mean 'cylinders'?",
        ),
        (
            "  ltr: {",
            "  ltrr: {",
            "p.yaml:4: burst.ltrr: Input should be 'ltr' or 'rtl', got 'ltrr'; did you mean 'ltr'?",
        ),
    ],
)
def test_typo_names_the_unknown_key_and_the_closest(old: str, new: str, message: str) -> None:
    with pytest.raises(ConfigError) as info:
        parse_protocol(PROTOCOL.replace(old, new), "p.yaml")
    assert str(info.value) == message


def test_unknown_key_without_a_close_one_lists_the_allowed_keys() -> None:
    with pytest.raises(ConfigError) as info:
        parse_protocol(PROTOCOL.replace("cycles: 5", "cycles: 5, colour: red"), "p.yaml")
    assert str(info.value) == (
        "p.yaml:4: burst.ltr.colour: unknown key 'colour' (allowed here: f_center, cycles, width, "
        "sigma_f, shape)"
    )


def test_typo_in_a_bench_file() -> None:
    text = load_bench().text
    assert "  piezo_stroke:" in text
    with pytest.raises(
        ConfigError,
        match=r"amplifier.piezo_strok: unknown key 'piezo_strok'; "
        r"did you mean 'piezo_stroke'\?$",
    ):
        parse_bench(text.replace("  piezo_stroke:", "  piezo_strok:"), "b.yaml")


def test_nested_typo_through_run_protocol(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    proto = tmp_path / "p.yaml"
    proto.write_text(PROTOCOL.replace("f_center: 8.92 kHz", "frequncy: 8.92 kHz"))
    assert rp.main([str(proto), "--dry-run"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (
        f"run_protocol: error: {proto}:4: burst.ltr.frequncy: unknown key 'frequncy'; "
        "did you mean 'f_center'?"
    )


def test_typo_in_a_chain_setting_through_biafc_simulate(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    from daq.cli.biafc import main

    out = tmp_path / "sim.h5"
    argv = ["simulate", "--direction", "ltr", "--amplitude", "1 um", "--set", "diamter=12mm"]
    assert main([*argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.endswith(
        "diamter: unknown key 'diamter'; did you mean 'diameter'? "
        "(already set: give that name to change it)"
    )
    assert len(err.splitlines()) == 1 and not out.exists()


def test_typo_in_a_chain_file(tmp_path: Path) -> None:
    from sim_backend.dem.spec import ChainFileError, default_chain_path, load_chain_spec

    f = tmp_path / "chain.yaml"
    f.write_text(default_chain_path().read_text().replace("preload:", "preloda:"))
    with pytest.raises(
        ChainFileError, match=r"preloda: unknown key 'preloda'; did you mean 'preload'\?$"
    ):
        load_chain_spec(f)
