"""Scenes: what a scene may drop (modes, nonlinearity, time, outputs), checked against the full
model, and the planner refusing what would be wrong."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from daq.cli.biafc import main
from instruments.burst import Burst
from sim_backend import dem
from sim_backend.dem.bands import cell_apparent_mass_kg
from sim_backend.dem.condense import condensation_error, condense_chain, drive_top_frequency_Hz
from sim_backend.dem.linear_response import linear_response
from sim_backend.dem.scene import (
    ENERGY_PROFILE_FACTOR,
    Scene,
    SceneTolerances,
    plan_scene,
    run_scene,
)

F_IN = {"ltr": 8.92e3, "rtl": 6.63e3}
RATE = 250e3


@pytest.fixture(scope="module")
def chain6() -> dem.Chain:
    return dem.build_chain(dem.default_chain_spec().model_copy(update={"n_modes": 6}))


def _drive(direction: str, amp: float, kind: str = "displacement") -> dem.Drive:
    return dem.Drive(direction, kind, amp, burst=Burst(F_IN[direction], 5.0))  # type: ignore[arg-type]


def _rel(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


def _energy_profile_error(v: np.ndarray, ref: np.ndarray) -> float:
    e, e_ref = np.sum(v**2, axis=-1), np.sum(ref**2, axis=-1)
    return float(np.abs(e - e_ref).max() / e_ref.max())


def test_condensed_modes_within_the_stated_bound(chain6: dem.Chain) -> None:
    """J = 6: the planner condenses the modes above ~100 kHz; the condensed run stays within the
    stated bounds of the full one (same nonlinear kernel, only the modes differ)."""
    T = 5e-3
    drive = _drive("ltr", 0.01 * chain6.delta0_m)
    plan = plan_scene(Scene(chain6, (drive,), T, RATE, record=("velocity",)))
    modes = plan.decisions[0]
    assert modes.aspect == "modes" and modes.reduced
    keep = plan.chain.n_modes
    assert 3 <= keep < 6
    eps = modes.error_bound
    assert eps is not None and eps <= 1e-3
    # the bound holds for the apparent mass itself, over the drive's band
    f_max = drive_top_frequency_Hz(drive)
    for i in (0, 15, 30):
        for f in np.linspace(100.0, f_max, 7):
            w = 2 * math.pi * f
            dm = cell_apparent_mass_kg(plan.chain, i, w) - cell_apparent_mass_kg(chain6, i, w)
            assert abs(dm) / chain6.mass_kg[i] <= eps * (1 + 1e-9)
    assert np.allclose(plan.chain.mass_kg, chain6.mass_kg)
    np.testing.assert_allclose(
        plan.chain.contact_dashpot_Ns_per_m(), chain6.contact_dashpot_Ns_per_m()
    )
    full = dem.simulate(chain6, [drive], duration_s=T, sample_rate_Hz=RATE).velocity
    red = dem.simulate(plan.chain, [drive], duration_s=T, sample_rate_Hz=RATE).velocity
    assert _energy_profile_error(red, full) <= ENERGY_PROFILE_FACTOR * eps
    assert _rel(red, full) <= math.pi * F_IN["ltr"] * T * eps
    assert _rel(red, full) > 0  # something was dropped


def test_planner_keeps_modes_that_would_be_wrong_to_condense(chain: dem.Chain) -> None:
    """Default chain, the paper's drive: mode 3 (45-60 kHz) is kept at the default tolerance, and
    condensing mode 2 (19-26 kHz, near the band) is refused at any sane tolerance; forcing it
    gives a wrong answer, so the refusal is not vacuous."""
    T = 5e-3
    drive = _drive("ltr", 0.01 * chain.delta0_m)
    plan = plan_scene(Scene(chain, (drive,), T, RATE, record=("velocity",)))
    assert plan.chain.n_modes == 3 and not plan.decisions[0].reduced
    loose = plan_scene(
        Scene(chain, (drive,), T, RATE, record=("velocity",)), SceneTolerances(mass_error=0.1)
    )
    assert loose.chain.n_modes == 2  # mode 3 may go at 10 %; mode 2 may not
    f_max = drive_top_frequency_Hz(drive)
    eps1 = condensation_error(chain, 1, f_max)
    assert eps1 > 0.1
    full = dem.simulate(chain, [drive], duration_s=T, sample_rate_Hz=RATE).velocity
    wrong = dem.simulate(condense_chain(chain, 1), [drive], duration_s=T, sample_rate_Hz=RATE)
    assert _energy_profile_error(wrong.velocity, full) > 0.05  # >> 2 x 1e-3 allowed
    assert _rel(wrong.velocity, full) > 0.5


@pytest.mark.parametrize(("direction", "kind"), [("ltr", "displacement"), ("rtl", "force")])
def test_linearised_matches_nonlinear_at_small_amplitude(
    chain: dem.Chain, direction: str, kind: str
) -> None:
    T = 10e-3
    rho = 0.01
    amp = rho * chain.delta0_m * (1.0 if kind == "displacement" else chain.K_lin)
    drive = _drive(direction, amp, kind)
    scene = Scene(chain, (drive, _drive(direction, 0.5 * amp, kind)), T, RATE,
                  record=("velocity", "drive"))  # fmt: skip
    plan = plan_scene(scene)
    assert plan.solver == "linear-modal"
    bound = plan.decisions[1].error_bound
    assert bound is not None and bound == pytest.approx(rho / 4)
    res = run_scene(plan)
    assert res.meta["solver"] == "linear-modal" and res.meta["fallback"] is False
    ref = dem.simulate(chain, list(scene.drives), duration_s=T, sample_rate_Hz=RATE)
    assert res.velocity is not None and res.drive is not None and res.displacement is None
    for r in range(2):
        assert _rel(res.velocity[r], ref.velocity[r]) <= bound
    np.testing.assert_allclose(res.drive, ref.drive, atol=1e-15 * amp)
    # the realised overlap change (every contact) is close to the prediction
    assert 0.5 * rho <= res.meta["realised_overlap_ratio"] <= 2 * rho


def test_planner_refuses_linearisation_when_it_would_be_wrong(chain: dem.Chain) -> None:
    big = Scene(chain, (_drive("ltr", 2 * chain.delta0_m),), 5e-3, RATE)
    plan = plan_scene(big)
    assert plan.solver == "nonlinear" and not plan.decisions[1].reduced
    # the same scene linearised is far off: the refusal matters
    lin = linear_response(chain, big.drives, duration_s=5e-3, sample_rate_Hz=RATE)
    ref = dem.simulate(chain, list(big.drives), duration_s=5e-3, sample_rate_Hz=RATE)
    assert lin.velocity is not None
    assert _rel(lin.velocity, ref.velocity) > 0.1
    # small amplitude but displacement recorded (rectified drift ~ 3 rho): refused
    small = Scene(chain, (_drive("ltr", 0.01 * chain.delta0_m),), 5e-3, RATE)
    assert plan_scene(small).solver == "nonlinear"
    # force drive with a free far end: rigid-body mode, refused
    free = dem.build_chain(dem.default_chain_spec().model_copy(update={"far_end": "free"}))
    tiny_force = _drive("ltr", 1e-3 * free.f0_N, "force")
    assert plan_scene(Scene(free, (tiny_force,), 5e-3, RATE, record=("velocity",))).solver == (
        "nonlinear"
    )


def test_early_stop_same_record_and_negligible_energy(dashpot_chain: dem.Chain) -> None:
    chain = dashpot_chain  # the contact dashpot drains the chain within the window
    T = 30e-3
    drive = _drive("ltr", 0.01 * chain.delta0_m)
    frac = 1e-3
    full = dem.simulate(chain, [drive], duration_s=T, sample_rate_Hz=RATE)
    stop = dem.simulate(chain, [drive], duration_s=T, sample_rate_Hz=RATE,
                        stop_energy_fraction=frac)  # fmt: skip
    n = stop.velocity.shape[-1]
    assert n < full.velocity.shape[-1]  # it stopped inside the window
    assert stop.time_s.size == n and int(stop.meta["samples_computed"][0]) == n
    np.testing.assert_array_equal(stop.velocity, full.velocity[..., :n])
    np.testing.assert_array_equal(stop.displacement, full.displacement[..., :n])
    np.testing.assert_array_equal(stop.drive, full.drive[..., :n])
    left = float(stop.meta["energy_left_rel"][0])
    assert 0 <= left <= frac
    # at the check before (0.5 ms = 125 samples earlier) the energy left was not negligible yet
    early = dem.simulate(chain, [drive], duration_s=(n - 1 - 125) / RATE, sample_rate_Hz=RATE)
    assert early.meta["energy_gain_J"][0] > frac * early.meta["input_work_J"][0]
    # the stated bound on what the truncated tail holds
    plan = plan_scene(Scene(chain, (_drive("ltr", 2 * chain.delta0_m),), T, RATE))
    assert plan.stop_energy_fraction == SceneTolerances().stop_energy_fraction
    res = run_scene(
        plan_scene(Scene(chain, (drive,), T, RATE, record=("velocity",)),
                   SceneTolerances(linear_error=0.0))
    )  # fmt: skip
    assert res.meta["solver"] == "nonlinear" and res.meta["stopped_early"]
    assert res.velocity is not None
    m = res.velocity.shape[-1]
    bound = float(res.meta["velocity_bound_after_stop_m_per_s"][0])
    assert np.abs(full.velocity[0, :, m:]).max() <= bound


def test_unrequested_outputs_are_not_produced(chain: dem.Chain) -> None:
    drive = _drive("rtl", 2 * chain.delta0_m)
    res = dem.simulate(chain, [drive], duration_s=2e-3, sample_rate_Hz=RATE,
                       cylinders=[31, 16], record=("velocity",))  # fmt: skip
    assert res.velocity.shape == (1, 2, 501)
    assert res.displacement.nbytes == 0 and res.drive.nbytes == 0
    full = dem.simulate(chain, [drive], duration_s=2e-3, sample_rate_Hz=RATE, cylinders=[31, 16])
    np.testing.assert_array_equal(res.velocity, full.velocity)
    with pytest.raises(ValueError, match="record"):
        dem.simulate(chain, [drive], duration_s=1e-3, record=("pressure",))
    sr = run_scene(plan_scene(Scene(chain, (drive,), 2e-3, RATE, (31,), ("displacement",))))
    assert sr.velocity is None and sr.drive is None
    assert sr.displacement is not None and sr.displacement.shape == (1, 1, 501)
    assert (
        plan_scene(Scene(chain, (drive,), 2e-3, RATE, (31,), ("displacement",)))
        .decisions[3]
        .reduced
    )


def test_cli_explain_names_every_decision(
    tmp_path: pytest.TempPathFactory, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["simulate", "--direction", "ltr", "--amplitude", "2 um", "--explain"]
    assert main(argv) == 0
    out = capsys.readouterr().out
    for aspect in ("modes:", "nonlinearity:", "time:", "output:"):
        assert aspect in out
    assert "kept" in out and "DROPPED" in out and "error bound" in out
    assert main(["simulate", "--direction", "ltr", "--amplitude", "2 um"]) == 2
    assert "--out" in capsys.readouterr().err


def test_cli_lean_runs_the_plan_and_stores_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``biafc simulate --lean``: at 0.01 um the plan takes the linear solution; the run file
    says so, carries the plan, and agrees with the full nonlinear run within the plan's bound."""
    import json

    from protocols.runfile import read_run

    common = ["simulate", "--direction", "ltr", "--amplitude", "0.01 um", "--duration", "8 ms"]
    lean, full = tmp_path / "lean.h5", tmp_path / "full.h5"
    assert main([*common, "--lean", "--out", str(lean)]) == 0
    assert "nonlinearity: DROPPED" in capsys.readouterr().out
    assert main([*common, "--out", str(full), "--no-error-estimate"]) == 0
    a, b = read_run(lean), read_run(full)
    assert a.simulation["integrator"] == "linear-modal"
    plan = json.loads(a.simulation["scene_plan_json"])
    assert plan["solver"] == "linear-modal" and len(plan["decisions"]) == 4
    bound = float(a.simulation["error_estimate_rel"])
    assert 0 < bound <= 1e-2
    va, vb = a.scans["ltr"].velocity[0], b.scans["ltr"].velocity[0]
    assert va.shape == vb.shape
    err = float(np.sqrt(np.mean((va - vb) ** 2)) / np.sqrt(np.mean(vb**2)))
    assert err <= bound, (err, bound)
    assert main([*common, "--lean", "--dt", "1 us", "--out", str(tmp_path / "x.h5")]) == 2
    assert "--lean picks the model itself" in capsys.readouterr().err
