"""Run files simulated by the DEM, written through ``protocols.runfile`` (for the tests).

Every direction and amplitude is one drive of a single batched ``dem.simulate`` call on the
default chain; every cylinder is recorded. The chain's quasi-bands go into ``/chain``.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from instruments.burst import Burst
from protocols.runfile import ChainInfo, RunFileWriter, ScanSpec

INPUTS_HZ = {"ltr": 8920.0, "rtl": 6630.0}
RATE_HZ = 200_000.0


def write_dem_run(
    path: Path,
    amplitudes_m: Sequence[float],
    *,
    directions: Sequence[str] = ("ltr", "rtl"),
    duration_s: float = 0.02,
    cycles: float = 5.0,
) -> Path:
    from sim_backend import dem

    chain = dem.build_chain(dem.default_chain_spec())
    bands = dem.quasi_bands(chain, 3)
    info = ChainInfo(
        lengths_m=np.asarray(chain.lengths_m),
        diameter_m=float(chain.diameter_m),
        f0_N=float(chain.f0_N),
        beta_c=float(chain.beta_c),
        onset_Hz=np.asarray(bands.onset_Hz),
        cutoff_Hz=np.asarray(bands.cutoff_Hz),
    )
    drives = [
        dem.Drive(
            direction=d,  # type: ignore[arg-type]
            kind="displacement",
            amplitude=float(a),
            burst=Burst(INPUTS_HZ[d], cycles=cycles),
        )
        for d in directions
        for a in amplitudes_m
    ]
    res = dem.simulate(chain, drives, duration_s=duration_s, sample_rate_Hz=RATE_HZ)
    time_s = np.asarray(res.time_s)
    cylinders = np.asarray(res.cylinders, dtype=np.int32)
    specs = [
        ScanSpec(d, np.asarray(amplitudes_m, float), "m", cylinders, time_s, INPUTS_HZ[d],
                 cycles=cycles, drive_units="m")
        for d in directions
    ]  # fmt: skip
    w = RunFileWriter.create(path, backend="dem", chain=info, scans=specs)
    r = 0
    for d in directions:
        for a in range(len(amplitudes_m)):
            for c in range(len(cylinders)):
                w.write_point(d, a, c, res.velocity[r, c], res.drive[r])
            r += 1
    w.close("complete")
    return path
