"""Bench assembly: a bench file -> the four instruments the run engine drives, real or simulated.

``simulated: true``: one :class:`sim_backend.bench.SimWorld` built from the bench file's
``simulation:`` section, the real drivers on its emulated transports, and its simulated
digitiser; waits run on the world's simulated clock. Otherwise: the drivers on real transports
(``open_transport``) and the NI-DAQmx digitiser (imported lazily).

The drivers are imported by name when a bench is assembled, so the rest of the engine (plan,
dry run, validation) works even where a driver stack is not installed.
"""

from __future__ import annotations

import importlib
from collections.abc import Mapping
from typing import Any

import numpy as np

from daq.engine.instruments import BenchInstruments
from protocols.bench import BenchFile, BenchSpec
from protocols.runfile import ChainInfo
from protocols.yamlfile import ConfigError

__all__ = [
    "AssemblyError",
    "assemble",
    "bench_chain_spec",
    "chain_info",
    "model_chain_info",
    "sim_world_config",
    "stage_settings",
]


class AssemblyError(ConfigError):
    """The bench cannot be assembled (missing driver, bad simulation setting); one line."""


def _chain_spec(bf: BenchFile) -> Any:
    from sim_backend import dem

    path = bf.chain_path()
    try:
        return dem.load_chain_with_settings(path, bf.bench.chain_set)
    except (dem.ChainFileError, OSError) as exc:
        field = "chain_set" if bf.bench.chain_set else "chain"
        raise bf.doc.error((field,), str(exc)) from None


def bench_chain_spec(bf: BenchFile) -> Any:
    """The bench's chain spec (its chain file with its ``chain_set``), validated; a bad one
    raises a one-line :class:`ConfigError` naming the bench file's field."""
    return _chain_spec(bf)


def chain_info(bf: BenchFile, n_bands: int = 3) -> ChainInfo:
    """The model's view of the bench's chain (lengths, contact constants, quasi-band edges)."""
    from sim_backend import dem

    chain = dem.build_chain(_chain_spec(bf))
    return model_chain_info(chain, dem.quasi_bands(chain, min(n_bands, chain.n_modes + 1)))


def model_chain_info(chain: Any, bands: Any) -> ChainInfo:
    """The run file's ``/chain`` of a built ``sim_backend.dem.Chain`` and its ``Bands``."""
    return ChainInfo(
        lengths_m=np.asarray(chain.lengths_m, dtype=np.float64),
        diameter_m=float(chain.diameter_m),
        f0_N=float(chain.f0_N),
        beta_c=float(chain.beta_c),
        onset_Hz=np.asarray(bands.onset_Hz, dtype=np.float64),
        cutoff_Hz=np.asarray(bands.cutoff_Hz, dtype=np.float64),
    )


def sim_world_config(
    bf: BenchFile, *, seed: int | None = None, faults: Mapping[str, Any] | None = None
) -> Any:
    """The :class:`SimWorldConfig` of a simulated bench file (``seed``/``faults`` override)."""
    from sim_backend.bench import ActuatorModel, FaultPlan, SimWorldConfig

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
        raise bf.doc.error(("simulation", "faults"), str(exc)) from None
    try:
        return SimWorldConfig(
            chain_spec=_chain_spec(bf),
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
        )
    except ValueError as exc:
        raise bf.doc.error(("simulation",), str(exc)) from None


def _import(module: str, name: str) -> Any:
    try:
        return getattr(importlib.import_module(module), name)
    except (ImportError, AttributeError) as exc:
        raise AssemblyError(f"driver {module}.{name} is not available ({exc})") from None


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
            min_signal_level=b.vibrometer.min_signal_level, commands=b.vibrometer.commands
        ),
    )
    stage = zaber.ZaberStage(transports["stage"], stage_settings(b, clock))
    # ask who they are now: a dead link or the wrong stage fails at connect, before anything
    # moves, and the snapshot records the identity
    generator.connect()
    vibrometer.connect()
    stage.connect([float(p) for p in b.positions_m()])
    return generator, vibrometer, stage


def assemble(
    bf: BenchFile, *, seed: int | None = None, faults: Mapping[str, Any] | None = None
) -> BenchInstruments:
    """Open every instrument of the bench (a simulated world when ``simulated: true``)."""
    b = bf.bench
    chain = chain_info(bf)
    if b.simulated:
        from sim_backend.bench import SimWorld

        world = SimWorld(sim_world_config(bf, seed=seed, faults=faults))
        try:
            transports = {
                "generator": world.transport("generator"),
                "vibrometer": world.transport("vibrometer", b.vibrometer.baud_rate),
                "stage": world.transport("stage", b.stage.baud_rate),
            }
            generator, vibrometer, stage = build_drivers(b, transports, world.clock)
        except (ImportError, AttributeError, NotImplementedError) as exc:
            raise AssemblyError(
                f"simulated bench: instrument drivers/emulators not available ({exc})"
            ) from None
        return BenchInstruments(
            generator=generator,
            vibrometer=vibrometer,
            stage=stage,
            digitiser=world.digitiser(b.daq.device),
            chain=chain,
            backend="sim",
            sleep=world.clock.sleep,
            world=world,
            extra_snapshot={
                "simulation": {"seed": world.config.seed, "faults": world.faults.as_dict()}
            },
        )
    open_transport = _import("instruments.transport", "open_transport")
    transports = {
        "generator": open_transport(
            b.generator.resource,
            name="generator",
            timeout_s=b.generator.timeout,
            baud_rate=b.generator.baud_rate,
        ),
        "vibrometer": open_transport(
            b.vibrometer.resource,
            name="vibrometer",
            timeout_s=b.vibrometer.timeout,
            baud_rate=b.vibrometer.baud_rate,
        ),
        "stage": open_transport(
            b.stage.resource,
            name="stage",
            timeout_s=b.stage.timeout,
            baud_rate=b.stage.baud_rate,
        ),
    }
    generator, vibrometer, stage = build_drivers(b, transports)
    digitiser = _import("daq.digitiser_nidaq", "NidaqDigitiser")(
        b.daq.device, max_rate_Hz=b.daq.max_rate
    )
    return BenchInstruments(generator, vibrometer, stage, digitiser, chain, "hardware")
