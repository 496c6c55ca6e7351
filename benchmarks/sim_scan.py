"""A full simulated scan through the real drivers: 31 cylinders x 2 directions x 8 amplitudes x
4 averages on the simulated bench with speed-up 0.

The amplitudes are peak actuator displacements, as a protocol gives them (0.025 to 5 um, log
spaced); the generator plays them through the bench's actuator (amplifier gain and piezo stroke:
1 um per generator volt peak on the shipped bench, so 0.05 to 10 Vpp). The table gives both.

Reports the wall time (``wall_s``) and how it splits between the DEM (``dem_s``: the 16 runs,
one per direction and amplitude, shared by every cylinder and average) and the software around
it (``rest_s``: drivers, wire protocols, emulators, stage moves, digitiser noise/quantisation),
plus the simulated bench time the same scan would take on the rig (``simulated_bench_s``).
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from daq.connect import connect_bench
from daq.engine.instruments import BenchInstruments
from instruments.burst import Burst
from instruments.interfaces import AcquisitionConfig, BurstConfig

F_IN_HZ = {"ltr": 8.92e3, "rtl": 6.63e3}
#: peak actuator displacement (m), as in a protocol
AMPLITUDES_M = tuple(float(a) for a in np.geomspace(0.025e-6, 5.0e-6, 8))
N_AVERAGES = 4
RATE_HZ = 200e3
DURATION_S = 30e-3
PRETRIGGER = 100
VIBROMETER_RANGE = "VD-09 50mm/s/V"


def generator_Vpp(world: Any, displacement_m: float) -> float:
    """Generator Vpp for a peak actuator displacement, through the simulated bench's actuator
    (to 12 digits: 5 um is 10 Vpp, the generator's limit, not one rounding above it)."""
    return float(f"{2.0 * float(world.config.actuator.generator_peak_V(displacement_m)):.12g}")


def scan(rig: BenchInstruments) -> dict[str, Any]:
    """Measure every (direction, amplitude, cylinder) with averages; returns counts and a
    per-direction summary (mean velocity record is kept only as energy figures)."""
    world = rig.world
    gen, stage, dig = rig.generator, rig.stage, rig.digitiser
    positions = world.cylinder_positions_m
    n_samples = round(DURATION_S * RATE_HZ) + PRETRIGGER
    dig.configure(
        AcquisitionConfig(
            sample_rate_Hz=RATE_HZ,
            n_samples=n_samples,
            n_pretrigger=PRETRIGGER,
            velocity_range_V=10.0,
            reference_range_V=10.0,
            trigger_source=world.config.trigger_terminal,
        )
    )
    rig.vibrometer.set_velocity_range(VIBROMETER_RANGE)  # 10 Vpp gives ~0.1 m/s near the piezo
    sens = rig.vibrometer.sensitivity_m_per_s_per_V()
    n_points = 0
    energy = np.zeros((2, len(AMPLITUDES_M), len(positions)))
    try:
        stage.home()
        for d, direction in enumerate(("ltr", "rtl")):
            channel = world.config.direction_channel[direction]
            for a, amp_m in enumerate(AMPLITUDES_M):
                amp = generator_Vpp(world, amp_m)
                gen.configure_burst(
                    channel,
                    BurstConfig(shape=Burst(F_IN_HZ[direction], cycles=5), amplitude_Vpp=amp),
                )
                gen.output(channel, True)
                for c, pos in enumerate(positions):
                    stage.move_to(float(pos))
                    acc = np.zeros(n_samples)
                    for _ in range(N_AVERAGES):
                        dig.arm()
                        gen.trigger()
                        acc += dig.read().velocity_V
                    v = acc / N_AVERAGES * sens
                    energy[d, a, c] = float(np.sum(v**2) / RATE_HZ)
                    n_points += 1
                gen.output(channel, False)
    finally:
        for inst in rig.all().values():
            inst.safe_state()
    return {"points": n_points, "energy": energy}


def run() -> dict[str, Any]:
    rig = connect_bench(seed=0)  # the shipped simulated bench (speed-up 0)
    world = rig.world
    t0 = time.perf_counter()
    result = scan(rig)
    wall = time.perf_counter() - t0
    stats = world.dem_stats
    return {
        "wall_s": wall,
        "dem_s": stats.dem_s,
        "rest_s": wall - stats.dem_s,
        "dem_calls": stats.calls,
        "dem_cache_hits": stats.cache_hits,
        "points": result["points"],
        "acquisitions": world.n_acquisitions,
        "simulated_bench_s": world.clock.now(),
        "target_s": 20.0,
        "table": amplitude_table(world, result["energy"]),
    }


def amplitude_table(world: Any, energy: np.ndarray) -> list[dict[str, Any]]:
    """One row per direction and amplitude: the peak displacement in um (the protocol's unit),
    the generator Vpp that played it, and the far/near energy ratio; ``energy``: ``[2, A, C]``
    (direction, amplitude, cylinder)."""
    rows = []
    for d, direction in enumerate(("ltr", "rtl")):
        far, near = (-1, 0) if d == 0 else (0, -1)
        for a, amp_m in enumerate(AMPLITUDES_M):
            rows.append(
                {
                    "direction": direction,
                    "amplitude_um": amp_m * 1e6,
                    "generator_Vpp": generator_Vpp(world, amp_m),
                    "far/near energy": float(energy[d, a, far])
                    / max(float(energy[d, a, near]), 1e-300),
                }
            )
    return rows
