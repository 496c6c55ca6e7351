"""benchmarks/sim_scan speaks in the protocol's unit: peak actuator displacement in um, with the
generator Vpp that played it beside (issue 19: it printed Vpp only)."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks import sim_scan
from daq.connect import connect_bench


def test_sim_scan_table_gives_um_and_the_vpp_that_played_them() -> None:
    rig = connect_bench(seed=0)
    try:
        energy = np.ones((2, len(sim_scan.AMPLITUDES_M), 31))
        rows = sim_scan.amplitude_table(rig.world, energy)
    finally:
        rig.close()
    assert list(rows[0])[:3] == ["direction", "amplitude_um", "generator_Vpp"]
    um = [r["amplitude_um"] for r in rows[:8]]
    assert um == pytest.approx(np.geomspace(0.025, 5.0, 8))
    # the shipped bench: gain 20, stroke 0.05 um/V -> 1 um per generator volt peak = 2 Vpp per um
    assert [r["generator_Vpp"] for r in rows[:8]] == pytest.approx(2.0 * np.array(um))
