"""The run plan: protocol x bench -> the ordered list of points, checked against the bench limits.

:func:`make_plan` is what ``--dry-run`` runs: every check that can be made before an instrument
is touched (amplitude limits of generator and piezo, cylinders of the chain, sample rate of the
digitiser; the positions inside the stage's reach are the bench file's own check), each
failure a one-line ``FILE:LINE: field: msg``.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from daq.engine.eta import RECORD_OVERHEAD_S, EtaEstimator, PointCosts, arms_burst, prior_costs
from instruments.units import format_quantity
from protocols.bench import BenchFile
from protocols.schema import ProtocolFile

__all__ = [
    "MAX_RECORD_SAMPLES",
    "MAX_RUN_BYTES",
    "RECORD_OVERHEAD_S",
    "Plan",
    "Point",
    "make_plan",
]


@dataclass(frozen=True)
class Point:
    """One measurement point: indices are 0-based into the scan's axes."""

    direction: str
    amplitude_index: int
    cylinder_index: int
    amplitude: float  # SI, in the protocol's unit (Vpp or m)
    generator_Vpp: float
    cylinder: int  # 1-based
    position_m: float


@dataclass(frozen=True)
class Plan:
    """Every point in measurement order, and the scan axes per direction."""

    points: tuple[Point, ...]
    directions: tuple[str, ...]
    amplitudes: NDArray[np.float64]  # [A], SI
    amplitude_units: str  # "V" (generator peak-to-peak) or "m"
    generator_Vpp: NDArray[np.float64]  # [A]
    cylinders: NDArray[np.int32]  # [C], 1-based
    positions_m: NDArray[np.float64]  # [C]
    estimated_s: float
    #: the prior cost per point on this bench (:mod:`daq.engine.eta`), refined during a run
    costs: PointCosts | None = None

    def eta(self, points: tuple[Point, ...] | None = None) -> EtaEstimator:
        """An ETA estimator for ``points`` (default: every point of the plan)."""
        pts = self.points if points is None else points
        costs = self.costs or PointCosts(self.estimated_s / max(self.n_points, 1), 0.0, "")
        return EtaEstimator(costs, arms_burst(pts))

    @property
    def n_points(self) -> int:
        return len(self.points)


def points_left(plan: Plan, done: dict[str, NDArray[np.uint8]]) -> tuple[Point, ...]:
    """The points of ``plan`` a run file's ``done`` masks (direction -> ``[A, C]``) do not
    hold as measured: what a resume measures, in the plan's order."""
    from protocols.runfile import PointState

    return tuple(
        p
        for p in plan.points
        if done[p.direction][p.amplitude_index, p.cylinder_index] != PointState.DONE
    )


def make_plan(pf: ProtocolFile, bf: BenchFile) -> Plan:
    """Check the protocol against the bench and order its points. Raises :class:`ConfigError`."""
    proto, bench = pf.protocol, bf.bench
    amps = proto.amplitude_values()
    kind = proto.amplitude_kind
    if kind == "displacement_m" and bench.amplifier.kind != "displacement":
        raise pf.error(("amplitudes",), "displacement amplitudes need a displacement actuator")
    vpp = np.array([bench.generator_Vpp(a, kind) for a in amps])
    _check_amplitudes(pf, bf, vpp)
    n = bench.n_cylinders
    chain = _model_chain(bf)  # once: the window plans on every pause in typing
    _check_model_cylinders(bf, chain)
    _check_simulated_stage(bf)
    cyl = proto.cylinder_numbers(n)
    bad = [int(c) for c in cyl if not 1 <= c <= n]
    if bad:
        raise pf.error(("cylinders",), f"cylinder {bad[0]} is not on this bench (1..{n})")
    # inside the stage's reach: the bench file holds every position within its soft limits,
    # and a simulated bench's soft limits within its travel (protocols.bench.BenchSpec)
    positions = bench.positions_m()[cyl - 1]
    acq = proto.acquisition
    if acq.rate > bench.daq.max_rate:
        raise pf.error(
            ("acquisition", "rate"),
            f"{acq.rate:.4g} S/s is above the digitiser's {bench.daq.max_rate:.4g} S/s",
        )
    if acq.n_samples() < 2:
        raise pf.error(("acquisition", "duration"), "the record has fewer than 2 samples")
    for d in proto.direction_list:
        burst = proto.burst[d].burst()
        if burst.duration_s > acq.duration:
            raise pf.error(
                ("burst", d),
                f"the burst lasts {burst.duration_s * 1e3:.4g} ms, longer than the record "
                f"({acq.duration * 1e3:.4g} ms, acquisition.duration): give a shorter burst "
                "(fewer cycles or a higher f_center) or a longer record",
            )
        _check_spectrum(pf, bf, d, burst)
    _check_transit(pf, bf, cyl, chain)
    _check_memory(pf, len(proto.direction_list) * len(amps) * len(cyl))
    axes = {
        "direction": list(enumerate(proto.direction_list)),
        "amplitude": list(enumerate(amps)),
        "cylinder": list(enumerate(cyl)),
    }
    points: list[Point] = []
    for combo in itertools.product(*(axes[name] for name in proto.order)):
        sel = dict(zip(proto.order, combo, strict=True))
        (_, d), (ai, a), (ci, c) = sel["direction"], sel["amplitude"], sel["cylinder"]
        points.append(Point(str(d), ai, ci, float(a), float(vpp[ai]), int(c), float(positions[ci])))
    pts = tuple(points)
    costs = prior_costs(proto, bf, [p.position_m for p in pts])
    est = EtaEstimator(costs, arms_burst(pts)).total_s()
    return Plan(
        points=pts,
        directions=tuple(proto.direction_list),
        amplitudes=amps,
        amplitude_units="V" if kind == "generator_Vpp" else "m",
        generator_Vpp=vpp,
        cylinders=cyl,
        positions_m=positions,
        estimated_s=float(est),
        costs=costs,
    )


#: the largest record (samples per channel) a protocol may ask for
MAX_RECORD_SAMPLES = 10_000_000
#: the most data a run may hold: velocity and drive, float32, every point (bytes)
MAX_RUN_BYTES = 2 * 2**30


def _check_amplitudes(pf: ProtocolFile, bf: BenchFile, vpp: NDArray[np.float64]) -> None:
    """Each amplitude within the generator's and the piezo's limits, said in the unit the
    protocol used (Vpp, Vpk or a displacement) and naming the bench field that binds."""
    from instruments.burst import burst_samples
    from instruments.keysight import arb_peak_factor, unequal_peaks
    from protocols.schema import amplitude_notation

    bench = bf.bench
    amp = bench.amplifier
    gen_max = bench.generator.max_amplitude
    # the generator may scale its amplitude to a burst's own peak-to-peak: a burst whose
    # peaks are unequal may then reach a little more than half its Vpp (as the driver checks)
    rate = bench.generator.sample_rate
    limits = _generator_limits(bf)
    factor = 1.0
    for d in pf.protocol.direction_list:
        burst = pf.protocol.burst[d].burst()
        if round(burst.duration_s * rate) + 1 <= limits.max_points:  # longer: refused later
            factor = max(factor, arb_peak_factor(burst_samples(burst, rate)))
    piezo_vpp = 2.0 * amp.piezo_max / amp.gain / factor
    max_vpp = min(gen_max, piezo_vpp)
    bench_name = Path(bf.doc.source).name
    written = pf.protocol.amplitudes
    texts = [written.start, written.stop] if not isinstance(written, list) else written
    notation = amplitude_notation(texts[0])

    def said(vpp_: float) -> str:  # a generator amplitude in the protocol's own unit
        if notation == "m":
            return format_quantity(vpp_ / (2.0 * bench.generator_V_per_m), "length")
        return f"{vpp_ / 2:.4g} Vpk" if notation == "Vpk" else f"{vpp_:.4g} Vpp"

    min_vpp = limits.min_amplitude_Vpp
    for i, v in enumerate(vpp):
        if v < min_vpp * (1 - 1e-12):
            raise pf.error(
                ("amplitudes",),
                f"amplitude {i + 1} ({said(v)}) is below {said(min_vpp)}, the smallest this "
                f"bench plays: it needs {v:.4g} Vpp from the generator, below the generator's "
                f"minimum {min_vpp:.4g} Vpp at high impedance",
            )
        if v <= max_vpp * (1 + 1e-12):
            continue
        shown, limit = said(v), said(max_vpp)
        if gen_max <= piezo_vpp:
            why = (
                f"it needs {v:.4g} Vpp from the generator, above generator.max_amplitude "
                f"{gen_max:.4g} Vpp ({bench_name})"
            )
        else:
            unequal = unequal_peaks(factor)
            why = (
                f"it gives up to {0.5 * v * factor * amp.gain:.4g} V at the piezo, above "
                f"amplifier.piezo_max {amp.piezo_max:.4g} V ({bench_name}, at gain "
                f"{amp.gain:.4g})" + (f"; {unequal}" if unequal else "")
            )
        raise pf.error(
            ("amplitudes",),
            f"amplitude {i + 1} ({shown}) is above {limit}, the limit of this bench: {why}",
        )


def _check_spectrum(pf: ProtocolFile, bf: BenchFile, direction: str, burst: Any) -> None:
    """The burst's band (f_center + 3 sigma_f) below the Nyquist frequency of the record and
    of the generator's waveform, and within the vibrometer range's frequency range."""
    from instruments.polytec import range_max_frequency_Hz

    acq, bench = pf.protocol.acquisition, bf.bench
    f_top = burst.f_center_Hz + 3.0 * burst.sigma_f_Hz
    where = ("burst", direction, "f_center")
    f_c = format_quantity(burst.f_center_Hz, "frequency")
    band = f"{f_c} burst (up to {format_quantity(f_top, 'frequency')} with its band)"
    if f_top >= acq.rate / 2:
        need = format_quantity(2 * f_top, "sample_rate")
        raise pf.error(
            where,
            f"the {band} is above the Nyquist frequency "
            f"{format_quantity(acq.rate / 2, 'frequency')} of the "
            f"{format_quantity(acq.rate, 'sample_rate')} record; record at more than {need} "
            f"(acquisition.rate; this bench allows "
            f"{format_quantity(bench.daq.max_rate, 'sample_rate')}) or lower f_center",
        )
    gen_rate = bench.generator.sample_rate
    limits = _generator_limits(bf)
    if gen_rate > limits.max_sample_rate_Hz:
        raise bf.doc.error(
            ("generator", "sample_rate"),
            f"{format_quantity(gen_rate, 'sample_rate')} is above the generator driver's "
            f"{format_quantity(limits.max_sample_rate_Hz, 'sample_rate')} waveform rate",
        )
    points = round(burst.duration_s * gen_rate) + 1  # as instruments.burst samples it
    if points > limits.max_points:
        raise pf.error(
            ("burst", direction),
            f"the burst ({format_quantity(burst.duration_s, 'time')}) takes {points:,} waveform "
            f"points at the generator's {format_quantity(gen_rate, 'sample_rate')} "
            f"({Path(bf.doc.source).name}: generator.sample_rate); the generator holds at most "
            f"{limits.max_points:,}",
        )
    if f_top >= bench.generator.sample_rate / 2:
        raise pf.error(
            where,
            f"the {band} is above the Nyquist frequency of the generator's "
            f"{format_quantity(bench.generator.sample_rate, 'sample_rate')} waveform "
            f"({Path(bf.doc.source).name}: generator.sample_rate)",
        )
    f_max = range_max_frequency_Hz(bench.vibrometer.range)
    if f_max is not None and f_top > f_max:
        raise pf.error(
            where,
            f"the {band} is above the {format_quantity(f_max, 'frequency')} the vibrometer "
            f"measures on {bench.vibrometer.range!r} "
            f"({Path(bf.doc.source).name}: vibrometer.range)",
        )


def _generator_limits(bf: BenchFile) -> Any:
    """The generator driver's limits for this bench, built as :mod:`daq.connect` builds them
    (waveform rate and length ceilings are the driver's)."""
    from instruments.keysight import GeneratorLimits

    b = bf.bench
    return GeneratorLimits(
        max_piezo_V=b.amplifier.piezo_max,
        amplifier_gain=b.amplifier.gain,
        max_amplitude_Vpp=b.generator.max_amplitude,
    )


def _model_chain(bf: BenchFile) -> Any:
    """The bench's chain as the model builds it (``sim_backend.dem.Chain``)."""
    from daq.chain_info import chain_spec
    from sim_backend import dem

    return dem.build_chain(chain_spec(bf))


def _check_simulated_stage(bf: BenchFile) -> None:
    """A simulated bench's stage microstep is the simulated stage's: another one (a bench
    written for another stage, with only ``microstep`` given) put every cylinder where the
    laser was not, and every point failed with its signal lost (a reviewer)."""
    stage = bf.bench.stage
    if bf.bench.simulation is None:
        return
    from sim_backend.emulators.zaber import STAGE_MODELS
    from sim_backend.simbench.emulated import SIMULATED_RESOLUTION, SIMULATED_STAGE

    if stage.resolution != SIMULATED_RESOLUTION:  # refused at connect, after the dry run
        raise bf.doc.error(
            ("stage", "resolution"),
            f"{stage.resolution} microsteps a step, but the simulated {SIMULATED_STAGE} runs "
            f"at {SIMULATED_RESOLUTION}",
        )
    full_step = STAGE_MODELS[SIMULATED_STAGE][1]
    if stage.microstep is None:
        return
    if not math.isclose(stage.microstep * stage.resolution, full_step, rel_tol=1e-6):
        raise bf.doc.error(
            ("stage", "microstep"),
            f"{stage.microstep * 1e6:.6g} um at resolution {stage.resolution} is not the "
            f"simulated stage's ({full_step / stage.resolution * 1e6:.6g} um: the simulated "
            f"bench moves an {SIMULATED_STAGE})",
        )


def _check_model_cylinders(bf: BenchFile, chain: Any) -> None:
    """A simulated bench places as many cylinders as its chain has: more positions than the
    model's cylinders passed the dry run and failed the run at the first extra one (an
    IndexError); fewer left the model's far end unmeasurable."""
    if bf.bench.simulation is None:
        return
    n_model = chain.n
    if bf.bench.n_cylinders != n_model:
        field = "chain" if bf.bench.chain else "cylinder_positions"
        raise bf.doc.error(
            (field,),
            f"{bf.bench.n_cylinders} cylinder positions, but the simulated chain has "
            f"{n_model} cylinders: give cylinder_positions one per cylinder of the chain",
        )


def _check_transit(
    pf: ProtocolFile, bf: BenchFile, cylinders: NDArray[np.int32], chain: Any
) -> None:
    """The record holds each burst and its transit to the farthest cylinder measured: at
    least one contact's crossing time sqrt(m0 / K) per contact, ``m0`` the lightest
    cylinder's rigid (non-resonating) mass and ``K`` the linearised contact stiffness of the
    bench's chain: no wave crosses faster, so a shorter record cannot hold its arrival."""
    proto = pf.protocol
    if not chain.K_lin > 0:  # preload 0 N: no linear wave speed, no bound to check against
        return
    per_contact = math.sqrt(float(np.min(chain.m0_kg)) / float(chain.K_lin))
    n = bf.bench.n_cylinders
    for d in proto.direction_list:
        burst = proto.burst[d].burst()
        far = int(np.max(cylinders - 1)) if d == "ltr" else int(np.max(n - cylinders))
        far_cyl = far + 1 if d == "ltr" else n - far
        need = burst.duration_s + far * per_contact
        if proto.acquisition.duration < need:
            raise pf.error(
                ("acquisition", "duration"),
                f"{format_quantity(proto.acquisition.duration, 'time')} cannot hold the {d} "
                f"burst ({format_quantity(burst.duration_s, 'time')}) and its transit to "
                f"cylinder {far_cyl} (at least {format_quantity(far * per_contact, 'time')} "
                f"over {far} contacts); record at least {format_quantity(need, 'time')}",
            )


def _check_memory(pf: ProtocolFile, n_points: int) -> None:
    """The record and the run's data within :data:`MAX_RECORD_SAMPLES` and
    :data:`MAX_RUN_BYTES`, before anything is allocated."""
    acq = pf.protocol.acquisition
    samples = acq.n_samples()
    if samples > MAX_RECORD_SAMPLES:
        raise pf.error(
            ("acquisition", "duration"),
            f"a record of {samples:,} samples per channel "
            f"({format_quantity(acq.duration + acq.pre_trigger, 'time')} at "
            f"{format_quantity(acq.rate, 'sample_rate')}) is above the bound of "
            f"{MAX_RECORD_SAMPLES:,}; shorten it or lower the rate",
        )
    data = n_points * samples * 2 * 4  # velocity and drive, float32
    if data > MAX_RUN_BYTES:
        raise pf.error(
            ("acquisition", "duration"),
            f"the run would hold {data / 2**30:.3g} GiB ({n_points:,} points x {samples:,} "
            f"samples x 2 channels x 4 bytes), above the bound of "
            f"{MAX_RUN_BYTES / 2**30:g} GiB; measure fewer points or shorter records",
        )
