"""One way from a bench file to connected drivers (``daq.connect.connect_bench``): the simulated
bench and the lab bench go through the same driver construction, from the same fields."""

from __future__ import annotations

import importlib
from typing import Any

import pytest

import daq.connect
from daq.connect import connect_bench
from instruments.errors import ReplyError
from instruments.interfaces import Digitiser, FunctionGenerator, Stage, Vibrometer
from protocols.bench import default_bench_path, load_bench, parse_bench

from .helpers import cable_lab_bench

ROOT = default_bench_path().parent


def test_default_is_the_shipped_simulated_bench_with_its_fields() -> None:
    bench = connect_bench()
    assert bench.backend == "sim" and bench.world is not None
    assert isinstance(bench.generator, FunctionGenerator)
    assert isinstance(bench.vibrometer, Vibrometer)
    assert isinstance(bench.stage, Stage)
    assert isinstance(bench.digitiser, Digitiser)
    snap = bench.snapshot()
    spec = load_bench().bench
    assert snap["stage"]["soft_limits_m"] == pytest.approx(list(spec.stage.soft_limits))
    assert snap["generator"]["limits"]["max_piezo_V"] == spec.amplifier.piezo_max
    assert snap["generator"]["limits"]["amplifier_gain"] == spec.amplifier.gain
    assert snap["vibrometer"]["velocity_range"] == spec.vibrometer.range
    assert "33522B" in snap["generator"]["identity"]  # identified at connect


def test_a_path_and_overrides_are_accepted() -> None:
    bench = connect_bench(ROOT / "sim_bench.yaml", seed=7, faults={"stage_stall": True})
    assert bench.world.config.seed == 7 and bench.world.faults.stage_stall


def test_lab_bench_builds_its_drivers_exactly_like_the_simulated_one(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The lab bench file, with its transports replaced by a simulated rig's, gives drivers
    with the same settings as the simulated bench file: there is one construction path."""
    cables = cable_lab_bench(monkeypatch)
    lab_file = load_bench(ROOT / "lab_bench.yaml")
    lab = connect_bench(lab_file)
    sim = connect_bench()
    assert lab.backend == "hardware" and lab.world is None
    lab_spec = lab_file.bench
    assert {name: (resource, timeout) for name, resource, timeout in cables} == {
        "generator": (lab_spec.generator.resource, lab_spec.generator.timeout),
        "vibrometer": (lab_spec.vibrometer.resource, lab_spec.vibrometer.timeout),
        "stage": (lab_spec.stage.resource, lab_spec.stage.timeout),
    }
    a, b = lab.snapshot(), sim.snapshot()
    assert a["generator"]["limits"] == b["generator"]["limits"]
    for key in ("soft_limits_m", "speed_m_per_s", "settle_s", "microstep_m"):
        assert a["stage"][key] == b["stage"][key], key
    assert a["digitiser"] == {"device": lab_spec.daq.device}


def test_a_missing_driver_is_one_line(monkeypatch: pytest.MonkeyPatch) -> None:
    import sys

    monkeypatch.setitem(sys.modules, "daq.digitiser_nidaq", None)  # import fails
    monkeypatch.setattr(
        daq.connect, "build_drivers", lambda b, transports, clock=None: (None, None, None)
    )
    import instruments.transport

    monkeypatch.setattr(instruments.transport, "open_transport", lambda *a, **k: None)
    with pytest.raises(daq.connect.ConnectError, match=r"daq\.digitiser_nidaq\.NidaqDigitiser"):
        connect_bench(ROOT / "lab_bench.yaml")


def test_a_failed_connect_closes_every_link_it_opened(monkeypatch: pytest.MonkeyPatch) -> None:
    """A second reader: with the NI driver missing, the three links stayed open; the window's
    next Connect then met a COM port still held ("Access is denied" on Windows)."""
    import sys

    import instruments.transport

    closed: list[str] = []

    class Link:
        def __init__(self, resource: str, **kw: Any) -> None:
            self.name = kw["name"]

        def close(self) -> None:
            closed.append(self.name)

    monkeypatch.setattr(instruments.transport, "open_transport", Link)
    nidaq = importlib.import_module("daq.digitiser_nidaq")
    # the NI driver missing: said before any link is opened (it was found after all three)
    monkeypatch.setitem(sys.modules, "daq.digitiser_nidaq", None)  # import fails
    with pytest.raises(daq.connect.ConnectError):
        connect_bench(ROOT / "lab_bench.yaml")
    assert closed == []
    # a stage that fails at connect: every link opened is closed, the card's task too
    monkeypatch.setitem(sys.modules, "daq.digitiser_nidaq", nidaq)

    class Card:
        def __init__(self, *a: Any, **k: Any) -> None:
            pass

        def close(self) -> None:
            closed.append("digitiser")

    monkeypatch.setattr(nidaq, "NidaqDigitiser", Card)

    def stage_dead(b: Any, transports: Any, clock: Any = None) -> Any:
        raise ConnectionError("stage: no reply")

    monkeypatch.setattr(daq.connect, "build_drivers", stage_dead)
    with pytest.raises(ConnectionError):
        connect_bench(ROOT / "lab_bench.yaml")
    assert closed == ["generator", "vibrometer", "stage", "digitiser"]


def test_the_bench_files_level_full_scale_reaches_the_vibrometer(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """``vibrometer.level_full_scale`` (a controller reading 0-775, say) is what the driver
    divides by; before, the bench file refused the key and the driver kept 100."""
    text = default_bench_path().read_text()
    assert "level_full_scale" not in text
    text = text.replace("vibrometer:\n", "vibrometer:\n  level_full_scale: 775\n", 1)
    path = tmp_path / "bench.yaml"
    path.write_text(text)
    bench = connect_bench(path)
    emulated = bench.world._inst.vibrometer  # type: ignore[union-attr]
    emulated.level_scale = 775
    level = bench.vibrometer.signal_level()  # the world sets the emulator's level as it reads
    assert 0.2 < level < 1 and level == pytest.approx(emulated.signal_level, abs=1 / 775)
    default = connect_bench()
    default.world._inst.vibrometer.level_scale = 775  # type: ignore[union-attr]
    with pytest.raises(ReplyError, match=r"above the full scale 100 \(vibrometer\.level_full"):
        default.vibrometer.signal_level()


def test_the_bench_files_dem_cache_MB_reaches_the_simulated_bench(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """docs/performance.md names ``dem_cache_MB`` as the simulated bench's cache bound; before,
    a bench file could not set it (unknown key)."""
    text = default_bench_path().read_text()
    text = text.replace("  dem_duration: 30 ms\n", "  dem_duration: 30 ms\n  dem_cache_MB: 64\n", 1)
    path = tmp_path / "bench.yaml"
    path.write_text(text)
    assert connect_bench(path).world.config.dem_cache_MB == 64  # type: ignore[union-attr]
    assert connect_bench().world.config.dem_cache_MB == 512  # type: ignore[union-attr]


def test_the_bench_files_visa_backend_reaches_every_transport(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """``visa_backend: "@ivi"`` (the NI-VISA or Keysight IO Libraries of the PC); before, every
    VISA resource opened on pyvisa-py whatever the PC had."""
    import instruments.transport

    cable_lab_bench(monkeypatch)
    seen: list[str] = []
    opened = instruments.transport.open_transport

    def record(resource: str, **kw: Any) -> Any:
        seen.append(kw["visa_backend"])
        return opened(resource, **kw)

    monkeypatch.setattr(instruments.transport, "open_transport", record)
    text = (
        (ROOT / "lab_bench.yaml").read_text().replace('visa_backend: "@py"', 'visa_backend: "@ivi"')
    )
    connect_bench(parse_bench(text, str(ROOT / "lab_bench.yaml")))
    assert seen == ["@ivi"] * 3


def test_a_stages_reply_is_waited_for_seconds_not_a_minute() -> None:
    """A second reader: stage.timeout (60 s, documented "per move") was the wait for every
    reply, so a dead stage cost a minute at connect, at each poll and at the safe state; a
    move's own bound comes from its distance and speed."""
    spec = load_bench(ROOT / "lab_bench.yaml").bench
    assert spec.stage.timeout == 2.0 == spec.vibrometer.timeout


def test_a_stage_timeout_set_in_the_bench_file_is_the_wait_for_its_replies(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Not only the default: a bench file's own ``stage.timeout`` reaches the stage's link."""
    path = ROOT / "lab_bench.yaml"
    text = path.read_text().replace("  settle: 0.2 s\n", "  settle: 0.2 s\n  timeout: 0.7 s\n")
    bench = parse_bench(text, str(path))
    assert bench.bench.stage.timeout == pytest.approx(0.7)
    cables = cable_lab_bench(monkeypatch)
    connect_bench(bench).close()
    assert {name: timeout for name, _, timeout in cables}["stage"] == pytest.approx(0.7)
