"""The whole simulated bench through the REAL drivers (Keysight, Polytec, Zaber on their
emulators, the simulated digitiser): a triggered record equals the DEM within the noise, the
physics shows through the instruments, and every injected fault surfaces as the driver's clear
error with the generator left safe."""

from __future__ import annotations

import numpy as np
import pytest

from daq.connect import connect_bench
from daq.engine.instruments import BenchInstruments as SimRig
from instruments.burst import Burst, burst_samples
from instruments.errors import (
    InstrumentTimeout,
    NotHomedError,
    ReplyError,
    SignalLostError,
    StallError,
)
from instruments.interfaces import (
    Acquisition,
    AcquisitionConfig,
    BurstConfig,
    Digitiser,
    FunctionGenerator,
    Stage,
    Vibrometer,
)
from sim_backend import dem
from sim_backend.simbench import SimWorld, SimWorldConfig

from .conftest import delayed

RATE = 200e3
ACQ = AcquisitionConfig(sample_rate_Hz=RATE, n_samples=6100, n_pretrigger=100)
F_IN = {"ltr": 8.92e3, "rtl": 6.63e3}
#: the most sensitive range that does not clip at 10 Vpp: the far end of the gap stays visible
RANGE = "VD-09 10mm/s/V"


def new_rig(seed: int | None = None) -> SimRig:
    """The shipped simulated bench, connected as the lab's would be (homed, digitiser set)."""
    rig = connect_bench(seed=seed)
    rig.vibrometer.set_velocity_range(RANGE)
    rig.stage.home()
    rig.digitiser.configure(ACQ)
    return rig


@pytest.fixture(scope="module")
def rig() -> SimRig:
    return new_rig(seed=5)


def safe(rig: SimRig) -> None:
    """Every instrument's safe state (outputs off, stage stopped, acquisition stopped)."""
    for inst in rig.all().values():
        inst.safe_state()


def burst(rig: SimRig, direction: str, vpp: float) -> int:
    channel = rig.world.config.direction_channel[direction]
    rig.generator.safe_state()
    rig.generator.configure_burst(
        channel, BurstConfig(shape=Burst(F_IN[direction], cycles=5), amplitude_Vpp=vpp)
    )
    rig.generator.output(channel, True)
    return channel


def shot(rig: SimRig, cylinder: int) -> Acquisition:
    rig.stage.move_to(float(rig.world.cylinder_positions_m[cylinder - 1]))
    rig.digitiser.arm()
    rig.generator.trigger()
    return rig.digitiser.read()


def outputs_off(rig: SimRig) -> bool:
    return not any(ch.output_on for ch in rig.world._inst.generator.channels.values())


def test_drivers_satisfy_the_interfaces(rig: SimRig) -> None:
    assert isinstance(rig.generator, FunctionGenerator)
    assert isinstance(rig.vibrometer, Vibrometer)
    assert isinstance(rig.stage, Stage)
    assert isinstance(rig.digitiser, Digitiser)
    assert "33522B" in rig.generator.identify()


def test_cylinder_31_through_the_drivers_equals_the_dem(rig: SimRig) -> None:
    vpp = 6.0
    burst(rig, "ltr", vpp)
    acq = shot(rig, 31)
    assert acq.meta["cylinder"] == 31
    sens = rig.vibrometer.sensitivity_m_per_s_per_V()
    delay = rig.vibrometer.signal_delay_s()
    measured = acq.velocity_V * sens
    chain = dem.build_chain(dem.default_chain_spec())
    shape = Burst(F_IN["ltr"], cycles=5)
    samples = burst_samples(shape, 1e6)
    drive = dem.Drive(
        direction="ltr",
        kind="displacement",
        amplitude=rig.world.config.actuator.drive_amplitude(vpp / 2),
        waveform=(samples, (samples.size - 1) / shape.duration_s),  # the burst's own carrier
    )
    res = dem.simulate(chain, [drive], duration_s=0.03, sample_rate_Hz=RATE)
    # between the DEM's samples by scipy's cubic spline: linear interpolation takes 0.14 % off
    # the burst at 500 kS/s, more than the noise at this amplitude
    expected = delayed(res.time_s, res.velocity[0, 30], acq.time_s - delay)
    cfg = rig.world.config
    noise = np.sqrt(
        cfg.vibrometer_noise_m_per_s_rms**2
        + (cfg.digitiser_noise_V_rms * sens) ** 2
        + (20.0 / 2**cfg.adc_bits * sens) ** 2 / 12
    )
    resid = measured - expected
    assert np.max(np.abs(expected)) > 100 * noise
    assert np.std(resid) < 1.3 * noise  # equal within the noise
    # the reference channel is the drive: generator peak = Vpp / 2
    assert np.max(np.abs(acq.reference_V)) == pytest.approx(vpp / 2, rel=0.01)
    rig.generator.safe_state()


def _energy(acq: Acquisition) -> float:
    return float(np.sum(acq.velocity_V**2))


def _band_peak_Hz(acq: Acquisition) -> float:
    x = acq.velocity_V * np.hanning(acq.velocity_V.size)
    spec = np.abs(np.fft.rfft(x))
    freq = np.fft.rfftfreq(x.size, 1.0 / acq.sample_rate_Hz)
    band = (freq > 4e3) & (freq < 12e3)
    return float(freq[band][np.argmax(spec[band])])


@pytest.mark.parametrize("direction", ["ltr", "rtl"])
def test_physics_through_the_instruments(rig: SimRig, direction: str) -> None:
    near, far = (1, 31) if direction == "ltr" else (31, 1)
    ratio = {}
    for vpp in (0.05, 10.0):
        burst(rig, direction, vpp)
        ratio[vpp] = _energy(shot(rig, far)) / _energy(shot(rig, near))
    assert ratio[0.05] < 0.01  # band-gap blocking
    assert ratio[10.0] > 10 * ratio[0.05]  # nonlinear transmission
    peak = _band_peak_Hz(shot(rig, far))
    if direction == "ltr":
        assert peak < F_IN["ltr"] - 500  # down-conversion
    else:
        assert peak > F_IN["rtl"] + 500  # up-conversion
    rig.generator.safe_state()
    assert outputs_off(rig)


def test_output_off_nothing_moves(rig: SimRig) -> None:
    channel = burst(rig, "ltr", 10.0)
    rig.generator.output(channel, False)
    acq = shot(rig, 1)
    assert np.max(np.abs(acq.reference_V)) < 0.01
    assert np.std(acq.velocity_V) < 0.01


def test_between_cylinders_low_signal_level(rig: SimRig) -> None:
    pos = rig.world.cylinder_positions_m
    rig.stage.move_to(float(0.5 * (pos[3] + pos[4])))
    with pytest.raises(SignalLostError):
        rig.vibrometer.check_signal()
    rig.stage.move_to(float(pos[4]))
    assert rig.vibrometer.check_signal() > 0.5


# --- faults ---------------------------------------------------------------------------------
def test_fault_generator_silent() -> None:
    rig = new_rig()
    burst(rig, "ltr", 1.0)
    rig.world.faults.generator_silent = True
    with pytest.raises(InstrumentTimeout, match="generator"):
        rig.generator.wait_complete()
    safe(rig)  # never raises on a dead link
    rig.world.faults.clear()  # the link comes back: the run engine's safe state reaches it
    safe(rig)
    assert outputs_off(rig)


def test_fault_scpi_error_in_the_queue() -> None:
    rig = new_rig()
    rig.world.faults.generator_scpi_error = '-222,"Data out of range"'
    with pytest.raises(ReplyError, match="-222"):
        burst(rig, "rtl", 1.0)
    assert outputs_off(rig)


def test_fault_stage_stall() -> None:
    rig = new_rig()
    burst(rig, "ltr", 1.0)
    rig.world.faults.stage_stall = True
    with pytest.raises(StallError):
        rig.stage.move_to(float(rig.world.cylinder_positions_m[20]))
    safe(rig)
    assert outputs_off(rig)


def test_fault_stage_loses_homing() -> None:
    rig = new_rig()
    burst(rig, "ltr", 1.0)
    rig.world.faults.stage_lost_homing = True
    with pytest.raises(NotHomedError):
        rig.stage.move_to(float(rig.world.cylinder_positions_m[10]))
    safe(rig)
    assert outputs_off(rig)
    rig.stage.home()  # homing again recovers
    rig.stage.move_to(float(rig.world.cylinder_positions_m[10]))


def test_fault_digitiser_timeout_and_nan() -> None:
    rig = new_rig()
    burst(rig, "ltr", 1.0)
    rig.world.faults.digitiser_timeout = True
    with pytest.raises(InstrumentTimeout, match="digitiser"):
        shot(rig, 2)
    rig.world.faults.clear()
    rig.world.faults.digitiser_nan = True
    acq = shot(rig, 2)
    assert np.all(np.isnan(acq.velocity_V)) and acq.meta["fault"] == "digitiser_nan"
    safe(rig)
    assert outputs_off(rig)


def test_fault_vibrometer_signal_lost() -> None:
    rig = new_rig()
    burst(rig, "ltr", 1.0)
    rig.stage.move_to(float(rig.world.cylinder_positions_m[0]))
    assert rig.vibrometer.check_signal() > 0.5
    rig.world.faults.vibrometer_signal_lost = True
    with pytest.raises(SignalLostError):
        rig.vibrometer.check_signal()
    safe(rig)
    assert outputs_off(rig)


def test_simulated_time_accounts_moves_without_waiting() -> None:
    rig = new_rig()  # the shipped simulated bench runs at speed-up 0
    t0 = rig.world.clock.now()
    pos = rig.world.cylinder_positions_m
    rig.stage.move_to(float(pos[30]))
    travel = abs(float(pos[30]) - rig.world.config.stage_travel_m[0])
    assert rig.world.clock.now() - t0 >= travel / rig.world.config.stage_speed_m_per_s


def test_world_transports_are_transports_and_unknown_names_refused() -> None:
    from instruments.interfaces import Transport

    world = SimWorld(SimWorldConfig())
    for name in ("generator", "vibrometer", "stage"):
        assert isinstance(world.transport(name), Transport)
    with pytest.raises(ValueError, match="oscilloscope"):
        world.transport("oscilloscope")


def test_speedup_makes_simulated_time_take_wall_time() -> None:
    import time

    world = SimWorld(SimWorldConfig(speedup=100.0))
    t0 = time.perf_counter()
    world.clock.sleep(1.0)  # 1 simulated second at 100x: 10 ms of wall time
    assert time.perf_counter() - t0 >= 0.009
    assert world.clock.now() == pytest.approx(1.0)


def test_a_seeded_simulated_run_is_reproducible() -> None:
    def record(seed: int) -> np.ndarray:
        rig = new_rig(seed=seed)
        burst(rig, "rtl", 2.0)
        return np.concatenate([shot(rig, c).velocity_V for c in (30, 31, 31)])

    first = record(3)
    assert np.array_equal(first, record(3))
    assert not np.array_equal(first, record(4))
