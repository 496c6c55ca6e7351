"""Steps split at the bursts' start and end (sim_backend.dem.split_steps): convergence with the
contact dashpot on, the wall's work, force drives, and what stays bit for bit."""

from __future__ import annotations

import numpy as np

from instruments.burst import Burst, burst_samples
from sim_backend import dem
from sim_backend.dem.errors import rel_l2

RATE = 250e3


def _run(chain: dem.Chain, drives: list[dem.Drive], **kw: object) -> dem.SimResult:
    return dem.simulate(chain, drives, sample_rate_Hz=RATE, record=("velocity",), **kw)  # type: ignore[arg-type]


def test_yoshida6_converges_past_the_burst_end_with_the_dashpot_on(
    dashpot_chain: dem.Chain,
) -> None:
    """The burst's end (0.56 ms) falls inside a step; the wall's velocity jumps there and the
    contact dashpot's force with it. Split there, yoshida6 and blanes-moan4 with Heun kicks
    change by < 1e-8 from 62.5 ns to 31.25 ns (not split, as before: 2.8e-7 and 3.3e-8)."""
    chain = dashpot_chain
    drive = dem.Drive("ltr", "displacement", 0.01 * chain.delta0_m, burst=Burst(8.92e3, 5.0))
    for integrator, kick in (("yoshida6", "midpoint"), ("blanes-moan4", "heun3")):
        v = [
            _run(chain, [drive], duration_s=1e-3, integrator=integrator, dt_s=dt,
                 dashpot_kick=kick).velocity
            for dt in (62.5e-9, 31.25e-9)
        ]  # fmt: skip
        change = float(rel_l2(v[0], v[1]).max())
        assert change < 1e-8, (integrator, change)


def test_the_wall_work_and_force_drives_stay_right(undamped: dem.Chain) -> None:
    """Undamped, H(end) - H(0) equals the input work summed over the sub-steps: the residual
    falls with the step (a wall: 1.1e-6 at 1 us, 1.9e-7 at 0.5 us; unsplit 4.6e-6, 3.3e-6), and
    a force burst, whose force has a kink at its ends, balances to < 1e-8 (unsplit 1.4e-6)."""
    burst = Burst(8.92e3, 5.0)
    wall = dem.Drive("ltr", "displacement", 2.0 * undamped.delta0_m, burst=burst)
    force = dem.Drive("ltr", "force", 1.5 * undamped.f0_N, burst=burst)
    res = {
        dt: dem.simulate(undamped, [wall, force], duration_s=2e-3, sample_rate_Hz=RATE, dt_s=dt)
        for dt in (1e-6, 0.5e-6)
    }
    wall_res = [abs(float(r.meta["energy_residual_rel"][0])) for r in res.values()]
    assert wall_res[1] < 0.3 * wall_res[0] and wall_res[1] < 5e-7, wall_res
    assert abs(float(res[1e-6].meta["energy_residual_rel"][1])) < 1e-8


def test_a_drive_without_breakpoints_inside_a_step_is_unchanged_bit_for_bit(
    dashpot_chain: dem.Chain,
) -> None:
    """A burst whose start and end are on the step grid (delay 1 ms, 5 cycles of 10 kHz:
    0.5 ms) and a table waveform (never split) give the same bits with and without splitting;
    a burst ending inside a step does not."""
    chain = dashpot_chain
    amp = 2.0 * chain.delta0_m
    on_grid = dem.Drive("ltr", "displacement", amp, burst=Burst(1e4, 5.0), delay_s=1e-3)
    table = dem.Drive("rtl", "displacement", amp, waveform=(burst_samples(Burst(6.63e3), 1e6), 1e6))
    inside = dem.Drive("ltr", "displacement", amp, burst=Burst(8.92e3, 5.0))
    kw = {"duration_s": 2e-3, "integrator": "yoshida6"}
    for drive in (on_grid, table):
        split = _run(chain, [drive], **kw)
        plain = _run(chain, [drive], split_at_burst_ends=False, **kw)
        np.testing.assert_array_equal(split.velocity, plain.velocity)
    split = _run(chain, [inside], **kw)
    plain = _run(chain, [inside], split_at_burst_ends=False, **kw)
    assert not np.array_equal(split.velocity, plain.velocity)


def test_a_drive_gives_the_same_bits_whatever_the_breakpoints_beside_it(
    dashpot_chain: dem.Chain,
) -> None:
    """Lanes of one chunk share their steps; a sample that holds some lanes' breakpoints is
    run once per group of lanes, so a drive's result is the same bits alone and beside drives
    with other burst lengths, delays, kinds and waveforms (chunks of 4 and of 8 lanes)."""
    chain = dashpot_chain
    d0, f0 = chain.delta0_m, chain.f0_N
    drives = [
        dem.Drive("ltr", "displacement", 2.0 * d0, burst=Burst(8.92e3, 5.0)),
        dem.Drive("ltr", "force", 0.5 * f0, burst=Burst(7.5e3, 5.0), delay_s=0.13e-3),
        dem.Drive("ltr", "displacement", 1.0 * d0, waveform=(burst_samples(Burst(9e3), 1e6), 1e6)),
        dem.Drive("ltr", "displacement", 0.5 * d0, burst=Burst(1e4, 5.0), delay_s=1e-3),
        dem.Drive("ltr", "displacement", 3.0 * d0, burst=Burst(8.0e3, 5.0), delay_s=0.0511e-3),
    ]
    drives += [
        dem.Drive("ltr", "displacement", (0.3 + 0.2 * k) * d0, burst=Burst(8.92e3 - 40 * k, 5.0))
        for k in range(12)
    ]
    kw = {"duration_s": 1.2e-3, "integrator": "blanes-moan4", "dashpot_kick": "heun3"}
    batch = _run(chain, drives, **kw)  # 17 drives: chunks of 8 lanes
    four = _run(chain, drives[:5], **kw)  # chunks of 4 lanes
    for r in range(5):
        alone = _run(chain, [drives[r]], **kw)
        np.testing.assert_array_equal(batch.velocity[r], alone.velocity[0])
        np.testing.assert_array_equal(four.velocity[r], alone.velocity[0])


def test_sub_step_drifts_use_the_formula_of_the_whole_steps() -> None:
    """``split_steps.drift_into`` (scalar, inside the kernel) and ``kernel.drift_coefficients``
    (numpy, for whole steps) are two writings of one formula: they must agree, rigid modes,
    damping and backward sub-steps included."""
    from sim_backend.dem.kernel import drift_coefficients
    from sim_backend.dem.split_steps import drift_into

    omega = np.array([[0.0, 2e3, 5e4, 5.2e5], [0.0, 1.1e3, 7e4, 4.9e5]])
    zeta = np.array([[0.0, 0.002, 0.01, 0.3], [0.0, 0.0, 0.05, 0.002]])
    for length in (2e-6, 0.37e-6, -1.1e-6, 5e-5):
        out = np.empty((*omega.shape, 4))
        drift_into(out, omega, zeta, length)
        np.testing.assert_allclose(out, drift_coefficients(omega, zeta, length), rtol=1e-12,
                                   atol=1e-22)  # fmt: skip
