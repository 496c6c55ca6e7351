"""The world's own pieces, on a stand-in DEM (fast): config, actuator, faults, signal chain,
the simulated digitiser, the trigger latch and the DEM cache."""

from __future__ import annotations

import math

import numpy as np
import pytest

from instruments.burst import Burst, burst_samples
from instruments.errors import InstrumentError, InstrumentTimeout, LimitError
from instruments.interfaces import AcquisitionConfig, Digitiser
from sim_backend.simbench import ActuatorModel, ChannelPlay, FaultPlan, SimWorld, SimWorldConfig
from sim_backend.simbench.dem_cache import DemKey, DemRecord
from sim_backend.simbench.signal_chain import (
    coerce_input_range,
    coerce_sample_rate,
    decoder_output,
    digitise,
    on_grid,
)

N_CYL = 5
POSITIONS = tuple(0.01 + 0.0136 * i for i in range(N_CYL))


def fake_dem(key: DemKey, waveform: np.ndarray) -> DemRecord:
    """Cylinder c moves at (c * 1 mm/s per um of drive) * sin(2 pi 8 kHz t) inside 1 ms."""
    n = round(key.duration_s * key.sample_rate_Hz)
    t = np.arange(n) / key.sample_rate_Hz
    base = np.where(t < 1e-3, np.sin(2 * math.pi * 8e3 * t), 0.0)
    scale = key.amplitude / 1e-6 * 1e-3
    sign = 1.0 if key.direction == "ltr" else -1.0
    vel = np.stack([sign * scale * (c + 1) * base for c in range(N_CYL)])
    return DemRecord(time_s=t, velocity_m_per_s=vel, drive=key.amplitude * base)


def make_world(**kw: object) -> SimWorld:
    cfg = SimWorldConfig(cylinder_positions_m=POSITIONS, dem_duration_s=2e-3, **kw)  # type: ignore[arg-type]
    world = SimWorld(cfg, simulator=fake_dem)
    world._inst.vibrometer.decoder_delay_s = 0.0  # records align sample by sample
    return world


def play(channel: int = 1, vpp: float = 2.0) -> ChannelPlay:
    return ChannelPlay(
        channel=channel,
        samples=burst_samples(Burst(8.92e3, cycles=5), 1e6),
        sample_rate_Hz=1e6,
        amplitude_Vpp=vpp,
    )


ACQ = AcquisitionConfig(sample_rate_Hz=200e3, n_samples=400, n_pretrigger=20, velocity_range_V=1.0)


def acquire(world: SimWorld, plays: list[ChannelPlay], config: AcquisitionConfig = ACQ):
    dig = world.digitiser()
    dig.configure(config)
    dig.arm()
    world.fire_trigger(plays)
    return dig.read()


def at_cylinder(world: SimWorld, c: int) -> None:
    world._inst.position_m = POSITIONS[c - 1]


# --- settings --------------------------------------------------------------------------------
def test_actuator_default_calibration_spans_linear_to_nonlinear() -> None:
    act = ActuatorModel()
    assert act.drive_amplitude(1.0) == pytest.approx(1e-6)  # 1 um per generator volt
    assert act.drive_amplitude(0.005) < 0.01 * 1.15e-6  # 10 mVpp: linear
    assert act.drive_amplitude(5.0) > 4 * 1.15e-6  # 10 Vpp: several delta0
    force = ActuatorModel(kind="force")
    assert force.drive_amplitude(5.0) == pytest.approx(50.0) and force.unit == "N"
    assert act.generator_peak_V(act.drive_amplitude(0.3)) == pytest.approx(0.3)


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"amplifier_gain_V_per_V": 0.0}, "amplifier_gain_V_per_V"),
        ({"piezo_m_per_V": float("nan")}, "piezo_m_per_V"),
        ({"kind": "voltage"}, "kind"),
    ],
)
def test_actuator_refuses_bad_values(kwargs: dict, field: str) -> None:
    with pytest.raises(ValueError, match=field):
        ActuatorModel(**kwargs)


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"direction_channel": {"ltr": 1, "rtl": 1}}, "direction_channel"),
        ({"direction_channel": {"ltr": 1}}, "direction_channel"),
        ({"direction_channel": {"ltr": 3, "rtl": 1}}, "direction_channel"),
        ({"spot_tolerance_m": 0.0}, "spot_tolerance_m"),
        ({"stage_travel_m": (0.3, 0.1)}, "stage_travel_m"),
        ({"cylinder_positions_m": (0.1, 0.9)}, "cylinder_positions_m"),
        ({"digitiser_noise_V_rms": -1.0}, "digitiser_noise_V_rms"),
        ({"adc_bits": 0}, "adc_bits"),
        ({"speedup": float("inf")}, "speedup"),
        ({"seed": -3}, "seed"),
        ({"dem_sample_rate_Hz": 0.0}, "dem_sample_rate_Hz"),
    ],
)
def test_config_refuses_bad_values_naming_the_field(kwargs: dict, field: str) -> None:
    with pytest.raises(ValueError, match=field):
        SimWorldConfig(**kwargs)


def test_fault_plan_from_mapping_and_clear() -> None:
    plan = FaultPlan.from_mapping({"stage_stall": True, "after_acquisitions": 3})
    assert plan.any() and not plan.active(2) and plan.active(3)
    with pytest.raises(ValueError, match="stage_explodes"):
        FaultPlan.from_mapping({"stage_explodes": True})
    with pytest.raises(ValueError, match="digitiser_nan"):
        FaultPlan(digitiser_nan="yes")  # type: ignore[arg-type]
    plan.clear()
    assert not plan.any() and plan.after_acquisitions == 0


# --- signal chain ----------------------------------------------------------------------------
def test_rate_and_range_coercion_like_a_daq() -> None:
    assert coerce_sample_rate(200e3, 2e6, 100e6) == 200e3
    assert coerce_sample_rate(300e3, 2e6, 100e6) == pytest.approx(100e6 / 333)
    with pytest.raises(LimitError, match="sample rate"):
        coerce_sample_rate(5e6, 2e6, 100e6)
    assert coerce_input_range(0.3) == 0.5 and coerce_input_range(10.0) == 10.0
    with pytest.raises(LimitError, match="range"):
        coerce_input_range(20.0)


def test_decoder_clips_and_adc_quantises() -> None:
    rng = np.random.default_rng(0)
    v = np.array([0.0, 0.05, 0.5])  # m/s, 10 mm/s/V: 0, 5 V, 50 V -> clipped at 10 V
    out = decoder_output(v, 0.01, 10.0, 0.0, rng)
    assert out.tolist() == pytest.approx([0.0, 5.0, 10.0])
    q = digitise(np.array([0.3, 2.0, -2.0]), 1.0, 4, 0.0, rng)
    lsb = 2.0 / 16
    assert q[0] == pytest.approx(round(0.3 / lsb) * lsb)
    assert q[1] == pytest.approx(1.0 - lsb) and q[2] == pytest.approx(-1.0)


def test_on_grid_copies_on_matching_grid_and_zero_pads() -> None:
    src_t = np.arange(10) / 10.0
    vals = np.arange(10.0)
    dst = (np.arange(14) - 2) / 10.0
    out = on_grid(src_t, vals, dst)
    assert out[:2].tolist() == [0.0, 0.0] and out[2:12].tolist() == vals.tolist()
    assert out[12:].tolist() == [0.0, 0.0]
    half = on_grid(src_t, vals, np.array([0.05, 0.15]))
    assert half.tolist() == pytest.approx([0.5, 1.5])


def test_on_grid_keeps_the_bursts_amplitude_across_a_fraction_of_a_sample() -> None:
    """The decoder's 7.3 us delay puts the record between the DEM's samples; linear
    interpolation took 1.0 % off an 8.92 kHz burst at 200 kS/s (0.14 % at 500 kS/s)."""
    for rate, most in ((200e3, 2e-4), (500e3, 1e-5)):
        t = np.arange(int(0.02 * rate)) / rate

        def burst(t: np.ndarray) -> np.ndarray:
            return np.exp(-(((t - 0.01) / 0.003) ** 2) / 2) * np.sin(2 * np.pi * 8920.0 * t)

        got = on_grid(t, burst(t), t - 7.3e-6)
        exact = burst(t - 7.3e-6)
        assert abs(np.linalg.norm(got) / np.linalg.norm(exact) - 1) < most, rate


# --- the world and its digitiser ------------------------------------------------------------
def test_sim_digitiser_is_a_digitiser() -> None:
    assert isinstance(make_world().digitiser(), Digitiser)


def test_record_is_the_scaled_dem_velocity_of_the_cylinder_under_the_laser() -> None:
    world = make_world(digitiser_noise_V_rms=0.0, vibrometer_noise_m_per_s_rms=0.0)
    at_cylinder(world, 3)
    acq = acquire(world, [play(vpp=2.0)])
    assert acq.meta["cylinder"] == 3 and acq.meta["direction"] == "ltr"
    key, norm = world.dem_key(play(vpp=2.0), 2e-3, 200e3)
    expected = fake_dem(key, norm).velocity_m_per_s[2] / 0.01  # volts, 10 mm/s/V
    got = acq.velocity_V[acq.time_s >= 0]
    lsb = 2.0 / 2**16
    assert np.max(np.abs(got - expected[: got.size])) <= lsb
    assert np.all(acq.velocity_V[acq.time_s < 0] == 0.0)
    # the reference channel is the generator output: peak amplitude_Vpp / 2 = 1 V
    assert np.max(np.abs(acq.reference_V)) == pytest.approx(1.0, abs=0.02)


def test_the_world_reads_the_range_from_the_emulators_table_not_the_drivers(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The world scaled the velocity with the driver's own range parser: a misread range would
    have been wrong on both sides alike, and no simulated run could show it."""
    import instruments.polytec

    monkeypatch.setattr(instruments.polytec, "parse_sensitivity", lambda name: 123.0)
    world = make_world(digitiser_noise_V_rms=0.0, vibrometer_noise_m_per_s_rms=0.0)
    at_cylinder(world, 3)
    acq = acquire(world, [play(vpp=2.0)])
    assert acq.meta["sensitivity_m_per_s_per_V"] == 0.01  # the emulator's VD-09 10mm/s/V


def test_rtl_channel_and_output_off() -> None:
    world = make_world(digitiser_noise_V_rms=0.0, vibrometer_noise_m_per_s_rms=0.0)
    at_cylinder(world, 1)
    acq = acquire(world, [play(channel=2)])
    assert acq.meta["direction"] == "rtl"
    quiet = acquire(world, [])  # no output on: nothing moves, no reference
    assert np.all(quiet.velocity_V == 0.0) and np.all(quiet.reference_V == 0.0)


def test_between_cylinders_no_signal() -> None:
    world = make_world()
    world._inst.position_m = 0.5 * (POSITIONS[0] + POSITIONS[1])
    assert world.cylinder_at(world._inst.position_m) is None
    assert world.signal_level() < 0.1
    acq = acquire(world, [play(vpp=10.0)])
    assert acq.meta["signal"] == "between cylinders"
    assert np.std(acq.velocity_V) < 0.1  # noise only; on target the burst gives ~ volts
    at_cylinder(world, 2)
    assert world.signal_level() > 0.5


def test_one_dem_run_serves_all_cylinders_and_averages_with_fresh_noise() -> None:
    world = make_world()
    records = []
    for c in range(1, N_CYL + 1):
        at_cylinder(world, c)
        for _ in range(3):
            records.append(acquire(world, [play()]).velocity_V)
    assert world.dem_stats.calls == 1 and world.dem_stats.cache_hits == 3 * N_CYL - 1
    assert not np.array_equal(records[0], records[1])  # fresh noise per average
    acquire(world, [play(vpp=3.0)])
    acquire(world, [play(channel=2)])
    assert world.dem_stats.calls == 3


def test_seeded_world_is_reproducible() -> None:
    def run(seed: int) -> np.ndarray:
        world = make_world(seed=seed)
        at_cylinder(world, 2)
        return np.concatenate([acquire(world, [play()]).velocity_V for _ in range(2)])

    assert np.array_equal(run(7), run(7))
    assert not np.array_equal(run(7), run(8))


def test_trigger_before_arm_or_on_wrong_terminal_times_out_in_simulated_time() -> None:
    world = make_world()
    dig = world.digitiser()
    dig.configure(ACQ)
    world.fire_trigger([play()])  # not armed yet: missed
    dig.arm()
    t0 = world.clock.now()
    with pytest.raises(InstrumentTimeout, match="no trigger"):
        dig.read()
    assert world.clock.now() - t0 == pytest.approx(ACQ.timeout_s)
    wrong = AcquisitionConfig(sample_rate_Hz=200e3, n_samples=100, trigger_source="/Dev1/PFI7")
    with pytest.raises(InstrumentTimeout, match="PFI7"):
        acquire(world, [play()], wrong)


def test_digitiser_faults() -> None:
    world = make_world()
    at_cylinder(world, 1)
    world.faults.digitiser_timeout = True
    with pytest.raises(InstrumentTimeout, match="digitiser"):
        acquire(world, [play()])
    world.faults.clear()
    world.faults.digitiser_nan = True
    assert np.all(np.isnan(acquire(world, [play()]).velocity_V))
    world.faults.clear()
    assert np.all(np.isfinite(acquire(world, [play()]).velocity_V))


def test_fault_after_n_acquisitions() -> None:
    world = make_world(faults=FaultPlan(digitiser_timeout=True, after_acquisitions=2))
    acquire(world, [play()])
    acquire(world, [play()])
    with pytest.raises(InstrumentTimeout):
        acquire(world, [play()])


def test_digitiser_refuses_bad_settings_before_acquiring() -> None:
    dig = make_world().digitiser()
    with pytest.raises(LimitError, match="velocity_channel"):
        dig.configure(
            AcquisitionConfig(sample_rate_Hz=1e5, n_samples=10, velocity_channel="Dev2/ai0")
        )
    with pytest.raises(LimitError, match="sample rate"):
        dig.configure(AcquisitionConfig(sample_rate_Hz=1e7, n_samples=10))
    with pytest.raises(InstrumentError, match="before configure"):
        dig.arm()
    with pytest.raises(InstrumentError, match="before arm"):
        dig.read()


def test_both_outputs_on_is_refused_clearly() -> None:
    world = make_world()
    with pytest.raises(InstrumentError, match="both generator outputs"):
        acquire(world, [play(1), play(2)])


def test_clock_accounts_the_record_time() -> None:
    world = make_world()
    t0 = world.clock.now()
    acquire(world, [play()])
    assert world.clock.now() - t0 == pytest.approx((ACQ.n_samples - ACQ.n_pretrigger) / 200e3)


def test_resumed_world_draws_the_same_noise_for_a_point() -> None:
    """Noise is keyed by what is measured, not by how many records came before, so a run
    resumed in a fresh world reproduces the uninterrupted run point for point."""
    full = make_world(seed=3)
    at_cylinder(full, 1)
    acquire(full, [play(vpp=1.0)])
    at_cylinder(full, 2)
    a = [acquire(full, [play(vpp=1.0)]).velocity_V for _ in range(2)]
    resumed = make_world(seed=3)
    at_cylinder(resumed, 2)
    b = [acquire(resumed, [play(vpp=1.0)]).velocity_V for _ in range(2)]
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    assert not np.array_equal(a[0], a[1])


def test_vibrometer_signal_loss_fault() -> None:
    world = make_world(digitiser_noise_V_rms=0.0)
    at_cylinder(world, 2)
    assert world.signal_level() > 0.5
    world.faults.vibrometer_signal_lost = True
    assert world.signal_level() == 0.0
    acq = acquire(world, [play(vpp=10.0)])
    assert acq.meta["signal"] == "lost"
    world.faults.clear()
    good = acquire(world, [play(vpp=10.0)])
    assert np.max(np.abs(good.velocity_V)) > 10 * np.std(acq.velocity_V)


def test_dem_cache_is_bounded_by_bytes_not_only_by_count() -> None:
    """A sweep of long windows: each record 11.2 MB (5 cylinders x 200,000 samples, the time and
    the drive); 20 distinct drives with a 64-record, 32 MB cache keep the newest two (before,
    all 20: 224 MB)."""
    from sim_backend.simbench.dem_cache import DemRunner

    runner = DemRunner(fake_dem, cache_size=64, cache_bytes=32 * 2**20)
    keys = [DemKey("ltr", "displacement", 1e-7 * (i + 1), "w", 1e6, 0.2, 1e6) for i in range(20)]
    for key in keys:
        rec = runner.record(key, np.zeros(4))
        assert rec.nbytes == 11_200_000
    assert len(runner) == 2 and runner.nbytes <= 32 * 2**20
    assert runner.record(keys[-1], np.zeros(4)) is rec  # the newest is a hit
    assert runner.stats.calls == 20 and runner.stats.cache_hits == 1
    # one record above the bound alone is still kept: the cylinders of one drive share it
    alone = DemRunner(fake_dem, cache_bytes=1)
    first = alone.record(keys[0], np.zeros(4))
    assert alone.record(keys[0], np.zeros(4)) is first and len(alone) == 1


def test_world_config_bounds_the_dem_cache_in_megabytes() -> None:
    world = make_world(dem_cache_MB=1.5)
    assert world._dem._max_bytes == round(1.5 * 2**20)
    with pytest.raises(ValueError, match="dem_cache_MB"):
        SimWorldConfig(dem_cache_MB=0)


def test_dem_cache_hits_a_cycle_of_drives_longer_than_itself() -> None:
    """Cylinder the outer loop of a sweep: 10 drives measured in turn on each of 5 cylinders,
    with room for 4 records. Least recently used out first dropped every record just before its
    next use (50 DEM runs, no hit); keeping a stable set, at least 3 of the 10 hit on each later
    pass (15 of 40 in all)."""
    from sim_backend.simbench.dem_cache import DemRunner

    runner = DemRunner(fake_dem, cache_size=4)
    keys = [DemKey("rtl", "displacement", 1e-7 * (i + 1), "w", 1e6, 2e-3, 1e6) for i in range(10)]
    for _cylinder in range(5):
        for key in keys:
            runner.record(key, np.zeros(4))
    assert runner.stats.cache_hits >= 4 * 3
    assert runner.stats.calls + runner.stats.cache_hits == 50
