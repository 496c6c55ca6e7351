"""The one way from a bench file to connected drivers: :func:`connect_bench`.

The lab, the simulated bench, the GUI, ``run_protocol``, ``biafc check``, the benchmarks and the
tests all open their instruments here, so the drivers on the simulated rig get exactly the
settings they would get on the lab's rig from the same fields.

Three things are called "bench"; this module joins them:

- a **bench file** (``protocols/benches/*.yaml``, schema ``protocols/bench.py``) describes a
  bench: addresses, limits, calibration, channels, cylinder positions;
- the **simulated rig** (``sim_backend.simbench``) is the world of emulated instruments and the
  DEM behind a bench file with ``simulated: true``;
- the **connected bench** (:class:`daq.engine.instruments.BenchInstruments`) is what the run
  engine drives: the four instruments, the chain's model and how to wait.

``simulated: true``: one :class:`sim_backend.simbench.SimWorld` built from the bench file's
``simulation:`` section, the real drivers on its emulated transports, and its simulated
digitiser; waits run on the world's simulated clock. Otherwise: the drivers on real transports
(``instruments.transport.open_transport``) and the NI-DAQmx digitiser (imported lazily).

The drivers are imported when a bench is connected, so the rest of the engine (plan, dry run,
validation) works where a driver stack is not installed.
"""

from __future__ import annotations

import contextlib
import importlib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from daq.chain_info import chain_info, chain_spec
from daq.engine.instruments import BenchInstruments
from protocols.bench import BenchFile, BenchSpec, load_bench
from protocols.yamlfile import ConfigError

__all__ = [
    "BenchInUse",
    "ConnectError",
    "build_drivers",
    "connect_bench",
    "sim_world_config",
    "stage_settings",
]


class ConnectError(ConfigError):
    """The bench cannot be connected (missing driver, bad simulation setting); one line."""


class BenchInUse(ConnectError):
    """Another live process drives an instrument of the bench (:mod:`daq.instrument_lock`);
    nothing was opened. One line."""


def sim_world_config(
    bf: BenchFile, *, seed: int | None = None, faults: Mapping[str, Any] | None = None
) -> Any:
    """The :class:`SimWorldConfig` of a simulated bench file (``seed``/``faults`` override)."""
    from sim_backend.simbench import ActuatorModel, FaultPlan, SimWorldConfig

    b: BenchSpec = bf.bench
    sim = b.simulation
    if sim is None:
        raise bf.doc.error(("simulated",), "not a simulated bench")
    amp = b.amplifier
    try:
        actuator = ActuatorModel(
            kind=amp.kind,
            amplifier_gain_V_per_V=amp.gain,
            piezo_m_per_V=amp.piezo_stroke,
            **({"force_N_per_V": amp.force_per_volt} if amp.force_per_volt else {}),
        )
        plan = FaultPlan.from_mapping(dict(faults if faults is not None else sim.faults))
    except ValueError as exc:
        raise bf.doc.error(("simulation", "faults"), str(exc).removeprefix("faults: ")) from None
    cache: dict[str, Any] = {} if sim.dem_cache_MB is None else {"dem_cache_MB": sim.dem_cache_MB}
    spec = chain_spec(bf)  # its own one-line error, naming the chain field (not "simulation")
    try:
        return SimWorldConfig(
            chain_spec=spec,
            direction_channel={str(k): int(v) for k, v in b.direction_channel.items()},
            actuator=actuator,
            cylinder_positions_m=tuple(float(p) for p in b.positions_m()),
            spot_tolerance_m=sim.spot_tolerance,
            stage_travel_m=(sim.stage_travel[0], sim.stage_travel[1]),
            stage_speed_m_per_s=b.stage.speed,
            stage_settle_s=b.stage.settle,
            vibrometer_range=b.vibrometer.range,
            vibrometer_full_scale_V=sim.vibrometer_full_scale,
            vibrometer_noise_m_per_s_rms=sim.vibrometer_noise,
            digitiser_noise_V_rms=sim.digitiser_noise,
            adc_bits=sim.adc_bits,
            max_rate_Hz=b.daq.max_rate,
            trigger_terminal=b.daq.trigger,
            seed=int(sim.seed if seed is None else seed),
            speedup=sim.speedup,
            faults=plan,
            dem_duration_s=sim.dem_duration,
            dem_integrator=sim.dem_integrator,
            **cache,
        )
    except ValueError as exc:  # named by the config's field: the bench's where the two agree
        key = str(exc).split(":", 1)[0]
        path = ("simulation", key) if key in type(sim).model_fields else ("simulation",)
        raise bf.doc.error(path, str(exc).removeprefix(f"{key}: ")) from None


def _import(module: str, name: str) -> Any:
    try:
        return getattr(importlib.import_module(module), name)
    except (ImportError, AttributeError) as exc:
        raise ConnectError(f"driver {module}.{name} is not available ({exc})") from None


def stage_settings(b: BenchSpec, clock: Any = None) -> Any:
    """The :class:`instruments.zaber.ZaberSettings` of the bench file's stage (model or
    microstep, resolution, device id, soft limits, speed, settling; ``clock``: the polling
    time source, ``None``: the system clock)."""
    zaber = importlib.import_module("instruments.zaber")
    kw: dict[str, Any] = {
        "model": b.stage.model,
        "microstep_m": b.stage.microstep,
        "resolution": b.stage.resolution,
        "device_id": b.stage.device_id,
        "soft_limits_m": (b.stage.soft_limits[0], b.stage.soft_limits[1]),
        "speed_m_per_s": b.stage.speed,
        "settle_s": b.stage.settle,
    }
    if clock is not None:
        kw["clock"] = clock
    return zaber.ZaberSettings(**kw)


def build_drivers(
    b: BenchSpec, transports: Mapping[str, Any], clock: Any = None
) -> tuple[Any, Any, Any]:
    """The generator, vibrometer and stage drivers on ``transports``, with the bench's limits
    and settings (``clock``: the stage's time source; ``None``: the system clock)."""
    keysight = importlib.import_module("instruments.keysight")
    polytec = importlib.import_module("instruments.polytec")
    zaber = importlib.import_module("instruments.zaber")
    limits = keysight.GeneratorLimits(
        max_piezo_V=b.amplifier.piezo_max,
        amplifier_gain=b.amplifier.gain,
        max_amplitude_Vpp=b.generator.max_amplitude,
    )
    generator = keysight.KeysightGenerator(transports["generator"], limits)
    vibrometer = polytec.PolytecVibrometer(
        transports["vibrometer"],
        polytec.PolytecSettings(
            min_signal_level=b.vibrometer.min_signal_level,
            level_full_scale=b.vibrometer.level_full_scale,
            commands=b.vibrometer.commands,
        ),
    )
    stage = zaber.ZaberStage(transports["stage"], stage_settings(b, clock))
    # ask who they are now: a dead link or the wrong stage fails at connect, before anything
    # moves, and the snapshot records the identity
    generator.connect()
    vibrometer.connect()
    stage.connect([float(p) for p in b.positions_m()])
    return generator, vibrometer, stage


def _bench_file(bench: BenchFile | str | Path | None) -> BenchFile:
    return bench if isinstance(bench, BenchFile) else load_bench(bench)


def connect_bench(
    bench: BenchFile | str | Path | None = None,
    *,
    seed: int | None = None,
    faults: Mapping[str, Any] | None = None,
) -> BenchInstruments:
    """Open every instrument of a bench file and return the connected bench.

    ``bench``: a loaded :class:`BenchFile`, a path to one, or ``None`` for the shipped simulated
    bench (``protocols/benches/sim_bench.yaml``). ``seed`` and ``faults`` override the
    ``simulation:`` section of a simulated bench (ignored on a real one). Nothing moves and no
    output is switched on: the drivers are opened and the generator and vibrometer identified.
    """
    bf = _bench_file(bench)
    b = bf.bench
    chain = chain_info(bf)
    if b.simulated:
        from sim_backend.simbench import SimWorld

        world = SimWorld(sim_world_config(bf, seed=seed, faults=faults))
        try:
            transports = {
                "generator": world.transport("generator"),
                "vibrometer": world.transport("vibrometer", b.vibrometer.baud_rate),
                "stage": world.transport("stage", b.stage.baud_rate),
            }
            generator, vibrometer, stage = build_drivers(b, transports, world.clock)
        except (ImportError, AttributeError, NotImplementedError) as exc:
            raise ConnectError(
                f"simulated bench: instrument drivers/emulators not available ({exc})"
            ) from None
        return BenchInstruments(
            generator=generator,
            vibrometer=vibrometer,
            stage=stage,
            digitiser=world.digitiser(b.daq.device, b.daq.terminal_config),
            chain=chain,
            backend="sim",
            sleep=world.clock.sleep,
            world=world,
            extra_snapshot={
                "simulation": {"seed": world.config.seed, "faults": world.faults.as_dict()}
            },
        )
    from daq.instrument_lock import InstrumentInUse, lock_instruments

    try:  # before anything is opened: a second process would mix its commands with a scan's
        locks = lock_instruments(
            {
                "generator": b.generator.resource,
                "vibrometer": b.vibrometer.resource,
                "stage": b.stage.resource,
                "DAQ device": b.daq.device,
            }
        )
    except InstrumentInUse as exc:
        raise BenchInUse(str(exc)) from None
    except OSError as exc:  # the cache folder cannot be written: no lock, so no connection
        raise ConnectError(
            f"cannot lock the bench's instruments in {exc.filename or 'the cache folder'} "
            f"({exc.strerror or exc}): set BIAFC_CACHE_DIR to a folder this user can write"
        ) from None
    try:
        return _connect_hardware(b, chain, locks)
    except BaseException:
        locks.release()
        raise


def _connect_hardware(b: BenchSpec, chain: Any, locks: Any) -> BenchInstruments:
    """The lab bench's drivers on real transports and the NI digitiser (its locks held)."""
    open_transport = _import("instruments.transport", "open_transport")
    links = {
        "generator": (b.generator.resource, b.generator.timeout, b.generator.baud_rate),
        "vibrometer": (b.vibrometer.resource, b.vibrometer.timeout, b.vibrometer.baud_rate),
        "stage": (b.stage.resource, b.stage.timeout, b.stage.baud_rate),
    }
    transports: dict[str, Any] = {}
    digitiser: Any = None
    try:
        # the NI driver and card first: a missing driver or a wrong device name is said before
        # any instrument is opened or written to (they were found after all three had been)
        digitiser = _import("daq.digitiser_nidaq", "NidaqDigitiser")(
            b.daq.device, max_rate_Hz=b.daq.max_rate, terminal_config=b.daq.terminal_config
        )
        for name, (resource, timeout_s, baud_rate) in links.items():
            transports[name] = open_transport(
                resource,
                name=name,
                timeout_s=timeout_s,
                baud_rate=baud_rate,
                visa_backend=b.visa_backend,
            )
        generator, vibrometer, stage = build_drivers(b, transports)
    except BaseException:  # every link opened so far is closed: a COM port held by a failed
        # connect refused the window's next Connect ("Access is denied"; a second reader)
        for transport in transports.values():
            with contextlib.suppress(Exception):
                transport.close()
        if digitiser is not None:
            with contextlib.suppress(Exception):
                digitiser.close()
        raise
    return BenchInstruments(generator, vibrometer, stage, digitiser, chain, "hardware", locks=locks)
