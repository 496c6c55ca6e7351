"""The run plan: protocol x bench -> the ordered list of points, checked against the bench limits.

:func:`make_plan` is what ``--dry-run`` runs: every check that can be made before an instrument
is touched (amplitude limits of generator and piezo, cylinders of the chain, positions inside the
stage travel, sample rate of the digitiser), each failure a one-line ``FILE:LINE: field: msg``.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from daq.engine.eta import RECORD_OVERHEAD_S, EtaEstimator, PointCosts, arms_burst, prior_costs
from instruments.units import format_quantity
from protocols.bench import BenchFile
from protocols.schema import ProtocolFile

__all__ = ["RECORD_OVERHEAD_S", "Plan", "Point", "make_plan"]


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


def make_plan(pf: ProtocolFile, bf: BenchFile) -> Plan:
    """Check the protocol against the bench and order its points. Raises :class:`ConfigError`."""
    proto, bench = pf.protocol, bf.bench
    amps = proto.amplitude_values()
    kind = proto.amplitude_kind
    if kind == "displacement_m" and bench.amplifier.kind != "displacement":
        raise pf.error(("amplitudes",), "displacement amplitudes need a displacement actuator")
    vpp = np.array([bench.generator_Vpp(a, kind) for a in amps])
    for i, v in enumerate(vpp):
        why = bench.amplitude_limit_error(float(v))
        if why is not None:
            shown = (
                format_quantity(float(amps[i]), "length")
                if kind == "displacement_m"
                else f"{amps[i]:.4g} Vpp"
            )
            raise pf.error(("amplitudes",), f"amplitude {i + 1} ({shown}): {why}")
    n = bench.n_cylinders
    cyl = proto.cylinder_numbers(n)
    bad = [int(c) for c in cyl if not 1 <= c <= n]
    if bad:
        raise pf.error(("cylinders",), f"cylinder {bad[0]} is not on this bench (1..{n})")
    positions = bench.positions_m()[cyl - 1]
    low, high = bench.stage.soft_limits
    if bench.simulated and bench.simulation is not None:
        low = max(low, bench.simulation.stage_travel[0])
        high = min(high, bench.simulation.stage_travel[1])
    for c, p in zip(cyl, positions, strict=True):
        if not low <= p <= high:
            raise bf.doc.error(
                ("cylinder_positions",),
                f"cylinder {c} at {p * 1e3:.4g} mm is outside the stage travel "
                f"{low * 1e3:.4g}..{high * 1e3:.4g} mm",
            )
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
                f"the burst lasts {burst.duration_s * 1e3:.4g} ms, longer than the record",
            )
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
