"""Names and output patterns that would escape runs/, collide or evaluate code are refused in
one line before anything runs (issue 15, names and paths)."""

from __future__ import annotations

from pathlib import Path

import pytest

from protocols.schema import parse_protocol
from protocols.yamlfile import ConfigError

SMOKE = (Path(__file__).parents[2] / "protocols" / "smoke.yaml").read_text()
PATTERN = 'output: "runs/{name}_{timestamp}.h5"'


@pytest.mark.parametrize("name", ["../../x", "'a\\0b'", '"a\\nb"', "'a b'", "x" * 65])
def test_unsafe_names_are_refused(name: str) -> None:
    with pytest.raises(ConfigError) as info:
        parse_protocol(SMOKE.replace("name: smoke", f"name: {name}"))
    msg = str(info.value)
    assert ":2: name:" in msg and "letters, digits" in msg and "\n" not in msg


@pytest.mark.parametrize(
    "pattern",
    ["{name.__class__}.h5", "{name.upper}.h5", "{name!r}.h5", "{0}.h5", "{name:>99}.h5"],
)
def test_output_pattern_takes_only_the_known_fields(pattern: str) -> None:
    with pytest.raises(ConfigError, match="not allowed in the output pattern"):
        parse_protocol(SMOKE.replace(PATTERN, f'output: "{pattern}"'))


def test_plain_pattern_and_name_still_work() -> None:
    pf = parse_protocol(SMOKE.replace(PATTERN, 'output: "runs/{name}_{date}.h5"'))
    assert pf.protocol.output_path().name.startswith("smoke_")


def test_an_output_pattern_not_ending_in_h5_is_refused(tmp_path: Path) -> None:
    """A run's log is RUN.log beside RUN.h5: runs named 'ltr.a' and 'ltr.b' shared 'ltr.log',
    and a run named 'x.log' found its own log in its place and failed (exit 1). A protocol
    stored in an older run file keeps its pattern: that run can still be resumed."""
    from protocols.schema import load_protocol

    text = SMOKE.replace(PATTERN, 'output: "runs/{name}_{timestamp}.log"')
    (tmp_path / "p.yaml").write_text(text)
    with pytest.raises(ConfigError, match=r":\d+: output: .*must end in \.h5"):
        load_protocol(tmp_path / "p.yaml")
    assert parse_protocol(text).protocol.output.endswith(".log")  # the stored protocol's path


@pytest.mark.parametrize("name", ["x.log", "ltr.a", "ltr"])
def test_a_run_file_not_named_h5_is_refused_before_anything_is_written(
    tmp_path: Path, name: str
) -> None:
    from daq.request import RequestError, validate_request

    with pytest.raises(RequestError, match=r"--out: .*a run file's name ends in \.h5"):
        validate_request("smoke", out=tmp_path / name)
    assert list(tmp_path.iterdir()) == []


def test_the_windows_protocol_check_refuses_a_pattern_not_ending_in_h5() -> None:
    """The window checks a protocol as it is typed (no file read, the output not checked yet):
    a pattern ending in .hdf5 passed its Dry run and was refused only at Start."""
    from daq.request import RequestError, validate_request

    pf = parse_protocol(SMOKE.replace(PATTERN, 'output: "runs/{name}_{timestamp}.hdf5"'))
    with pytest.raises(RequestError, match=r"output: .*must end in \.h5"):
        validate_request(pf, None, check_output=False)
    validate_request(parse_protocol(SMOKE), None, check_output=False)  # the shipped one passes
