"""Time integration: agreement with independent solutions, linear limit, band-gap blocking,
the nonlinear amplitude sweep (BiAFC), energy balance, robustness and convergence."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from instruments.burst import Burst, burst_samples
from sim_backend import dem
from sim_backend.dem.reference import linear_matrices, make_rhs
from sim_backend.dem.spec import DampingSpec

F_IN = {"ltr": 8.92e3, "rtl": 6.63e3}
RATE = 250e3


def _burst_drive(
    direction: str, amp: float, kind: str = "displacement", cycles: float = 5.0
) -> dem.Drive:
    burst = Burst(F_IN[direction], cycles)
    return dem.Drive(direction, kind, amp, burst=burst)  # type: ignore[arg-type]


def _oriented(v: np.ndarray, direction: str) -> np.ndarray:
    return v if direction == "ltr" else -v[::-1]


def _errors_against_solve_ivp(
    chain: dem.Chain, drives: list[dem.Drive], res: dem.SimResult
) -> list[float]:
    """Per drive, the largest velocity difference over the window between ``res`` and scipy's
    DOP853 (rtol 1e-10) on the plain NumPy model, relative to the largest velocity."""
    n_x = chain.n * (chain.n_modes + 1)
    t_end = float(res.time_s[-1])
    errors = []
    for r, drive in enumerate(drives):
        rhs, y0 = make_rhs(chain, drive)
        sol = solve_ivp(
            rhs, (0, t_end), y0, method="DOP853", t_eval=res.time_s, rtol=1e-10, atol=1e-14
        )
        v = _oriented(sol.y[n_x : n_x + chain.n], drive.direction)
        errors.append(float(np.abs(res.velocity[r] - v).max() / np.abs(v).max()))
    return errors


def test_matches_independent_solve_ivp_nonlinear(chain: dem.Chain) -> None:
    """The compiled splitting against scipy's DOP853 on the plain NumPy model (contacts open)."""
    T = 1.5e-3
    drives = [
        _burst_drive("ltr", 2.5 * chain.delta0_m),
        _burst_drive("rtl", 1.5 * chain.f0_N, kind="force"),
    ]
    res = dem.simulate(chain, drives, duration_s=T, sample_rate_Hz=RATE)
    for drive, err in zip(drives, _errors_against_solve_ivp(chain, drives, res), strict=True):
        assert err < 1e-4, (drive.direction, err)


@pytest.mark.parametrize("kick", ["midpoint", "heun3"])
@pytest.mark.parametrize("far_end", ["wall", "free"])
@pytest.mark.parametrize("n_cylinders", [1, 2, 3])
def test_short_chains_match_independent_solve_ivp(
    n_cylinders: int, far_end: str, kick: str
) -> None:
    """Chains of 1-3 cylinders, contact dashpot on: the kernel's first contact and far end are
    loops' edges of their own (the first cylinder's contact is also the far end for N = 1, and
    the loop between them is empty for N = 2); each against DOP853 on the NumPy model."""
    spec = dem.default_chain_spec().model_copy(
        update={
            "n_cylinders": n_cylinders,
            "length_first": 0.1,
            "length_last": 0.1,
            "far_end": far_end,
            "damping": DampingSpec(bending_mode_ratio=2e-3, contact_dashpot_ratio=5e-3),
        }
    )
    chain = dem.build_chain(spec)
    T = 0.6e-3
    drives = [_burst_drive("ltr", 2.5 * chain.delta0_m), _burst_drive("rtl", 1.5 * chain.delta0_m)]
    if far_end == "wall":  # a force drive with a free far end has a rigid-body mode: refused
        drives.append(_burst_drive("ltr", 1.5 * chain.f0_N, kind="force"))
    res = dem.simulate(
        chain, drives, duration_s=T, sample_rate_Hz=RATE, dt_s=0.25e-6, dashpot_kick=kick
    )
    for drive, err in zip(drives, _errors_against_solve_ivp(chain, drives, res), strict=True):
        assert err < 1e-5, (drive.direction, drive.kind, err)


def test_linear_limit_matches_linear_solution(undamped: dem.Chain) -> None:
    """At 1e-3 delta0 the chain is the linearised chain: compare with the linear ODE's solution."""
    chain = undamped
    T = 3e-3
    amp = 1e-3 * chain.delta0_m
    drive = _burst_drive("ltr", amp)
    M, K, C, b = linear_matrices(chain, "ltr")
    assert np.all(C == 0)
    minv = 1.0 / np.diag(M)
    n_x = M.shape[0]

    def rhs(t: float, y: np.ndarray) -> np.ndarray:
        x, v = y[:n_x], y[n_x:]
        return np.concatenate([v, minv * (b * drive.value(np.array([t]))[0] - K @ x)])

    res = dem.simulate(chain, [drive], duration_s=T, sample_rate_Hz=RATE)
    sol = solve_ivp(rhs, (0, T), np.zeros(2 * n_x), method="DOP853", t_eval=res.time_s,
                    rtol=1e-10, atol=1e-16)  # fmt: skip
    v_lin = sol.y[n_x : n_x + chain.n]
    err = np.linalg.norm(res.velocity[0] - v_lin) / np.linalg.norm(v_lin)
    assert err < 5e-3
    # and it scales linearly
    res2 = dem.simulate(chain, [_burst_drive("ltr", 2 * amp)], duration_s=T, sample_rate_Hz=RATE)
    err2 = np.linalg.norm(res2.velocity[0] - 2 * res.velocity[0]) / np.linalg.norm(res2.velocity)
    assert err2 < 5e-3


@pytest.mark.parametrize("direction", ["ltr", "rtl"])
def test_band_gap_turns_the_packet_near_the_predicted_cylinder(
    chain: dem.Chain, direction: str
) -> None:
    bands = dem.quasi_bands(chain, 2)
    f = F_IN[direction]
    if direction == "ltr":  # the cutoff slides down to f: the packet turns there
        turning = int(np.argmax(bands.cutoff_Hz[:, 1] < f))  # 0-based index
        ahead, behind = turning + 8, turning - 3
    else:  # the onset slides up to f, going from #31 towards #1
        turning = int(np.flatnonzero(bands.onset_Hz[:, 1] > f)[-1])
        ahead, behind = turning - 8, turning + 3
    assert 13 <= turning <= 17
    res = dem.simulate(
        chain, [_burst_drive(direction, 0.01 * chain.delta0_m, cycles=20)],
        duration_s=30e-3, sample_rate_Hz=RATE,
    )  # fmt: skip
    e = np.sum(res.velocity[0] ** 2, axis=-1)
    e /= e.max()
    assert e[behind] > 0.3
    assert e[ahead] < 0.05
    far = -1 if direction == "ltr" else 0
    assert e[far] < 1e-3


def _band_peak(v: np.ndarray, lo: float, hi: float) -> float:
    n = v.size
    spec = np.abs(np.fft.rfft(v * np.hanning(n), 4 * n))
    f = np.fft.rfftfreq(4 * n, 1 / RATE)
    m = (f > lo) & (f < hi)
    return float(f[m][np.argmax(spec[m])])


def test_amplitude_sweep_biafc(chain: dem.Chain) -> None:
    """Transmission grows by > 10x through ~delta0; the far end's peak moves down from 8.92 kHz
    (LTR) and up from 6.63 kHz (RTL), to near the end cylinders' band edges."""
    bands = dem.quasi_bands(chain, 2)
    lo, hi = bands.onset_Hz[:, 1].min(), bands.cutoff_Hz[:, 1].max()
    levels = np.array([0.01, 0.3, 1.0, 2.0, 4.0])
    drives = [_burst_drive(d, a * chain.delta0_m) for d in ("ltr", "rtl") for a in levels]
    res = dem.simulate(chain, drives, duration_s=30e-3, sample_rate_Hz=RATE)
    assert res.meta["finite"]
    n = levels.size
    for k, direction in enumerate(("ltr", "rtl")):
        v = res.velocity[k * n : (k + 1) * n]
        far, entry = (-1, 0) if direction == "ltr" else (0, -1)
        ratio = np.sum(v[:, far] ** 2, axis=-1) / np.sum(v[:, entry] ** 2, axis=-1)
        assert ratio[-1] > 10 * ratio[0], (direction, ratio)
        assert np.all(np.diff(ratio[1:]) > 0), (direction, ratio)  # grows through delta0
        peak = _band_peak(v[-1, far], lo, hi)
        if direction == "ltr":
            edge = bands.cutoff_Hz[-1, 1]  # the 110 mm cylinder's cutoff
            assert peak < F_IN["ltr"] - 0.5e3
        else:
            edge = bands.onset_Hz[0, 1]  # the 90 mm cylinder's onset
            assert peak > F_IN["rtl"] + 0.5e3
        assert abs(peak - edge) < 0.05 * edge, (direction, peak, edge)


def test_energy_balance_without_damping(undamped: dem.Chain) -> None:
    d0, f0 = undamped.delta0_m, undamped.f0_N
    drives = [
        _burst_drive("ltr", 2 * d0),
        _burst_drive("rtl", 2 * d0),
        _burst_drive("ltr", 2 * f0, kind="force"),
        _burst_drive("rtl", 0.5 * f0, kind="force"),
    ]
    res = dem.simulate(undamped, drives, duration_s=10e-3, sample_rate_Hz=RATE)
    assert not res.meta["damped"]
    assert np.all(res.meta["input_work_J"] > 0)
    assert np.all(np.abs(res.meta["energy_residual_rel"]) < 1e-4), res.meta["energy_residual_rel"]


def test_no_nan_at_twenty_delta0(chain: dem.Chain, undamped: dem.Chain) -> None:
    for c in (chain, undamped):
        drives = [
            _burst_drive("ltr", 20 * c.delta0_m),
            _burst_drive("rtl", 20 * c.delta0_m),
            _burst_drive("ltr", 20 * c.f0_N, kind="force"),
        ]
        res = dem.simulate(c, drives, duration_s=10e-3, sample_rate_Hz=RATE)
        assert res.meta["finite"]
        assert np.all(np.isfinite(res.displacement)) and np.all(np.isfinite(res.drive))
        assert np.abs(res.velocity).max() < 10.0  # m/s: bounded, physical
    assert np.all(np.abs(res.meta["energy_residual_rel"]) < 1e-3)


@pytest.mark.parametrize(("integrator", "order"), [("strang", 2), ("blanes-moan4", 4)])
def test_convergence_order(undamped: dem.Chain, integrator: str, order: int) -> None:
    drive = _burst_drive("ltr", 0.1 * undamped.delta0_m)
    runs = [
        dem.simulate(undamped, [drive], duration_s=3e-3, sample_rate_Hz=RATE,
                     integrator=integrator, dt_s=dt).velocity[0]
        for dt in (1e-6, 0.5e-6, 0.25e-6)
    ]  # fmt: skip
    e1 = np.linalg.norm(runs[0] - runs[1])
    e2 = np.linalg.norm(runs[1] - runs[2])
    assert e1 / e2 == pytest.approx(2**order, rel=0.3)


@pytest.mark.parametrize(("kick", "fourth_order"), [("heun3", True), ("midpoint", False)])
def test_heun_kicks_keep_blanes_moan4_fourth_order_with_dashpots(
    dashpot_chain: dem.Chain, kick: str, fourth_order: bool
) -> None:
    """On the damped chain a kick's force depends on the velocities it changes. Integrated to
    third order inside each kick (``heun3``), ``blanes-moan4`` stays fourth order at steps of
    1-2 us: the ratio of successive differences is 16. The default explicit midpoint's error
    does not cancel over this scheme's kicks (sum b^3 != 0): the ratio is about 3."""
    chain = dashpot_chain
    drive = _burst_drive("ltr", 0.1 * chain.delta0_m)
    runs = [
        dem.simulate(chain, [drive], duration_s=3e-3, sample_rate_Hz=RATE,
                     integrator="blanes-moan4", dt_s=dt, dashpot_kick=kick).velocity[0]  # type: ignore[arg-type]
        for dt in (2e-6, 1e-6, 0.5e-6)
    ]  # fmt: skip
    ratio = np.linalg.norm(runs[0] - runs[1]) / np.linalg.norm(runs[1] - runs[2])
    if fourth_order:
        assert ratio == pytest.approx(16.0, rel=0.3)
    else:
        assert ratio < 8.0


def test_dashpot_kick_is_checked(chain: dem.Chain) -> None:
    with pytest.raises(ValueError, match="dashpot_kick"):
        dem.simulate(chain, [_burst_drive("ltr", 1e-7)], duration_s=1e-4,
                     dashpot_kick="rk4")  # type: ignore[arg-type]  # fmt: skip


def test_waveform_drive_matches_burst_and_mapping(chain: dem.Chain) -> None:
    burst = Burst(F_IN["rtl"], 5.0)
    samples = burst_samples(burst, 20e6)
    amp = 0.5 * chain.delta0_m
    d_burst = dem.Drive("rtl", "displacement", amp, burst=burst, delay_s=1e-4)
    d_wave = dem.Drive("rtl", "displacement", amp, waveform=(samples, 20e6), delay_s=1e-4)
    res = dem.simulate(chain, [d_burst, d_wave], duration_s=3e-3, sample_rate_Hz=RATE)
    v = res.velocity
    assert np.linalg.norm(v[1] - v[0]) / np.linalg.norm(v[0]) < 1e-3
    np.testing.assert_allclose(res.drive[0], d_burst.value(res.time_s), atol=1e-15)
    assert res.drive[0][res.time_s < 1e-4].max() == 0.0
    # recorded subset and 1-based numbering (rtl enters at #31)
    sub = dem.simulate(chain, [d_burst], duration_s=3e-3, sample_rate_Hz=RATE, cylinders=[31, 1])
    assert list(sub.cylinders) == [31, 1]
    np.testing.assert_allclose(sub.velocity[0], v[0][[30, 0]], rtol=0, atol=1e-15)
    assert np.abs(v[0][30]).max() > 10 * np.abs(v[0][0]).max()


def test_bad_arguments(chain: dem.Chain) -> None:
    with pytest.raises(ValueError, match="exactly one"):
        dem.Drive("ltr", "displacement", 1e-6)
    with pytest.raises(ValueError, match="direction"):
        dem.Drive("up", "displacement", 1e-6, burst=Burst(8e3))  # type: ignore[arg-type]
    d = _burst_drive("ltr", 1e-6)
    with pytest.raises(ValueError, match="integrator"):
        dem.simulate(chain, [d], duration_s=1e-3, integrator="euler")
    with pytest.raises(ValueError, match="cylinders"):
        dem.simulate(chain, [d], duration_s=1e-3, cylinders=[0])
    with pytest.raises(ValueError, match="duration"):
        dem.simulate(chain, [d], duration_s=-1.0)


@pytest.mark.parametrize("update", [{"n_modes": 6}, {"far_end": "free"}])
def test_six_modes_and_free_far_end(update: dict[str, object]) -> None:
    """Stiffer blocks (J = 6, modes to 210 kHz) get a smaller default step and stay accurate;
    a free far end (constant preload force) conserves energy too."""
    spec = dem.default_chain_spec().model_copy(
        update={**update, "damping": DampingSpec(bending_mode_ratio=0.0, contact_dashpot_ratio=0.0)}
    )
    chain = dem.build_chain(spec)
    drives = [_burst_drive("ltr", 2 * chain.delta0_m), _burst_drive("rtl", 2 * chain.f0_N, "force")]
    res = dem.simulate(chain, drives, duration_s=5e-3, sample_rate_Hz=RATE)
    ref = dem.simulate(chain, drives, duration_s=5e-3, sample_rate_Hz=RATE,
                       integrator="yoshida6", dt_s=0.125e-6)  # fmt: skip
    err = np.linalg.norm(res.velocity - ref.velocity, axis=-1) / np.linalg.norm(
        ref.velocity, axis=-1
    )
    assert err.max() < 1e-4
    assert np.all(np.abs(res.meta["energy_residual_rel"]) < 1e-4)
    if update.get("n_modes") == 6:
        assert res.meta["dt_s"] < 1e-6
