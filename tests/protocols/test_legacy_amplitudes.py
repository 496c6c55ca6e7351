"""A run started before amplitudes had to say Vpp or Vpk (issue 16) stored ``amplitudes: [1 V]``
(then read as Vpp): ``--resume`` of such an interrupted run still reads its protocol, as Vpp."""

from __future__ import annotations

from pathlib import Path

import h5py
import pytest

from daq.request import validate_request
from daq.store import StoreError, stored_request
from protocols.bench import load_bench
from protocols.legacy import upgrade_protocol_text
from protocols.schema import parse_protocol
from protocols.yamlfile import ConfigError
from tests.bad_inputs.test_request_cases import _run_file
from tests.engine.helpers import PROTOCOL

OLD = PROTOCOL.replace("[1 Vpp, 2 Vpp]", "[1 V, 2 V]")


def _old_run_file(tmp_path: Path) -> Path:
    """A killed run file whose stored protocol text is the old, bare-volt one."""
    path = _run_file(tmp_path)
    with h5py.File(path, "r+") as f:
        f.attrs["protocol_yaml"] = OLD
    return path


def test_the_schema_now_refuses_a_bare_volt() -> None:
    with pytest.raises(ConfigError, match="Vpp"):
        parse_protocol(OLD, "old.yaml")


def test_resume_alone_reads_an_old_files_bare_volts_as_vpp(tmp_path: Path) -> None:
    pf, _ = stored_request(_old_run_file(tmp_path))
    assert list(pf.protocol.amplitude_values()) == [1.0, 2.0]
    assert pf.protocol.amplitude_kind == "generator_Vpp"


def test_resume_of_an_old_file_with_the_protocol_written_in_vpp_is_allowed(
    tmp_path: Path,
) -> None:
    path = _old_run_file(tmp_path)
    given = parse_protocol(PROTOCOL, "proto.yaml")
    request = validate_request(given, load_bench(), resume=path)  # RequestError when refused
    assert request.protocol.protocol.amplitude_kind == "generator_Vpp"


def test_a_range_and_other_units_are_left_as_written() -> None:
    text = "name: x\namplitudes: {start: 10 mV, stop: 2 V, count: 3}\n"
    assert "10 mVpp" in upgrade_protocol_text(text) and "2 Vpp" in upgrade_protocol_text(text)
    for same in ("amplitudes: [2 um]\n", "amplitudes: [2 Vpk]\n", "- not a mapping\n", ":\n:"):
        assert upgrade_protocol_text(same) == same


def test_an_unreadable_stored_protocol_is_still_one_line(tmp_path: Path) -> None:
    path = _run_file(tmp_path)
    with h5py.File(path, "r+") as f:
        f.attrs["protocol_yaml"] = OLD.replace("[1 V, 2 V]", "[1 W]")
    with pytest.raises(StoreError, match="unreadable"):
        stored_request(path)
