"""Accuracy tooling: the cached converged reference, observed orders, the honesty of the
step-doubling error estimate, ``biafc accuracy`` and ``biafc simulate``'s error attributes."""

from __future__ import annotations

import itertools
import json
from dataclasses import replace
from pathlib import Path

import h5py
import numpy as np
import pytest

from daq.cli.biafc import main
from sim_backend import dem
from sim_backend.dem.accuracy import measure_fixed, observed_order
from sim_backend.dem.accuracy_scenes import AccuracyScene, builtin_scene
from sim_backend.dem.converged import ConvergedReference, converged_reference
from sim_backend.dem.errors import rel_l2


def _quick_reference(scene: AccuracyScene) -> ConvergedReference:
    return converged_reference(scene, dt0_s=0.125e-6, min_dt_s=62.5e-9)


@pytest.fixture(autouse=True)
def _cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    folder = tmp_path / "cache"
    monkeypatch.setenv("BIAFC_CACHE_DIR", str(folder))
    return folder


@pytest.fixture(scope="module")
def highamp() -> AccuracyScene:
    return builtin_scene("highamp", duration_s=2e-3)


def test_reference_cache_miss_then_hit(_cache: Path) -> None:
    scene = builtin_scene("linear", duration_s=0.5e-3)
    first = converged_reference(scene, dt0_s=0.25e-6, min_dt_s=0.125e-6)
    assert not first.from_cache and first.halvings == 1
    assert first.path.parent.parent == _cache and first.path.exists()
    second = converged_reference(scene, dt0_s=0.25e-6, min_dt_s=0.125e-6)
    assert second.from_cache
    np.testing.assert_array_equal(second.velocity, first.velocity)
    assert second.change_rel == first.change_rel
    # another amplitude, or another reference method, is another entry
    other = converged_reference(
        replace(scene, amplitude=2 * scene.amplitude), dt0_s=0.25e-6, min_dt_s=0.125e-6
    )
    assert not other.from_cache and other.path != first.path
    assert scene.digest("a") != scene.digest("b")


def test_observed_orders_two_and_four(highamp: AccuracyScene) -> None:
    ref = _quick_reference(highamp)
    for name, ladder, nominal in (
        ("strang", (0.4e-6, 0.2e-6, 0.1e-6), 2),
        ("yoshida4", (2e-6, 1e-6, 0.5e-6), 4),
    ):
        rows = [measure_fixed(highamp, ref, name, h) for h in ladder]
        p = observed_order([m.setting for m in rows], [m.err_worst for m in rows], ref.change_rel)
        assert p is not None
        assert abs(p - nominal) < 0.4, (name, p)
        assert rows[0].rhs_evals == len(dem.INTEGRATORS[name][2]) * rows[0].steps


def test_default_scheme_is_fourth_order_on_the_default_chain() -> None:
    """``biafc accuracy``'s chain (the default: contact dashpot off), linear scene: the default
    ``blanes-moan4`` keeps order 4 down to 0.25 us (1e-9), and Heun kicks change nothing there
    (no dashpot). The kernel before the steps holding a burst's end were split
    (``NUMERICS_VERSION`` 2) left an O(h^2) error from the wall's force kink there: local order
    1.6 from 0.5 to 0.25 us, and a reference too poor (change 7.9e-8) to fit an order at all."""
    scene = builtin_scene("linear", chain_spec=dem.default_chain_spec(), duration_s=2e-3)
    ref = _quick_reference(scene)
    ladder = (2e-6, 1e-6, 0.5e-6, 0.25e-6)
    rows = [measure_fixed(scene, ref, "blanes-moan4", h) for h in ladder]
    errs = [m.err_worst for m in rows]
    p = observed_order(list(ladder), errs, ref.change_rel)
    assert p is not None and p == pytest.approx(4.0, abs=0.1), (p, errs, ref.change_rel)
    assert errs[-1] < 3e-9
    local = [np.log2(a / b) for a, b in itertools.pairwise(errs)]
    assert min(local) > 3.8, local
    heun = measure_fixed(scene, ref, "blanes-moan4+heun3", 0.5e-6)
    assert heun.err_worst == rows[2].err_worst


def test_observed_order_ignores_floor_and_pre_asymptotic_points() -> None:
    h = [8.0, 4.0, 2.0, 1.0, 0.5]
    err = [0.5, 1e-3, 1.25e-4, 1.6e-5, 1.5e-5]  # pre-asymptotic, order 3, then a floor
    assert observed_order(h, err, floor_rel=2e-6) == pytest.approx(3.0, abs=0.05)
    assert observed_order(h, [0.5, 0.4, 0.3, 0.2, 0.1], floor_rel=1e-6) is None


@pytest.mark.parametrize(("integrator", "dt_s"), [("blanes-moan4", 2e-6), ("strang", 0.2e-6)])
def test_error_estimate_is_honest(highamp: AccuracyScene, integrator: str, dt_s: float) -> None:
    ref = _quick_reference(highamp)
    res = dem.simulate(
        highamp.chain(), [highamp.drive()], duration_s=highamp.duration_s,
        sample_rate_Hz=highamp.sample_rate_Hz, integrator=integrator, dt_s=dt_s,
        error_estimate=True,
    )  # fmt: skip
    true = float(rel_l2(res.velocity, ref.velocity[None]).max())
    estimate = float(res.meta["error_estimate_rel"][0])
    assert true > 20 * ref.change_rel  # the reference is good enough to judge
    assert true / 3 < estimate < 3 * true, (true, estimate)


def test_error_estimate_is_optional(highamp: AccuracyScene) -> None:
    res = dem.simulate(highamp.chain(), [highamp.drive()], duration_s=0.2e-3, sample_rate_Hz=250e3)
    assert "error_estimate_rel" not in res.meta


def test_cli_quick_json_and_plot(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    png = tmp_path / "wp.png"
    argv = ["accuracy", "--quick", "--json", "--scene", "linear", "--duration", "1 ms"]
    assert main([*argv, "--plot", str(png)]) == 0
    captured = capsys.readouterr()
    out = json.loads(captured.out)  # the progress display keeps to stderr
    from sim_backend.dem.accuracy import accuracy_runs

    n = accuracy_runs(quick=True)
    assert f"run {n}/{n}: linear: " in captured.err and "ETA 00:00" in captured.err
    (scene,) = out["scenes"]
    methods = {m["method"] for m in scene["measurements"]}
    assert methods == {
        "blanes-moan4",
        "blanes-moan4+heun3",
        "yoshida4",
        "suzuki4",
        "strang",
        "DOP853",
        "RK45",
    }
    assert not scene["reference"]["from_cache"]
    for m in scene["measurements"]:
        assert m["wall_s"] > 0 and m["rhs_evals"] >= m["steps"] > 0
        assert 0 <= m["err_driven"] <= m["err_worst"] and m["err_far"] <= m["err_worst"]
    assert set(scene["orders"]) == {
        "blanes-moan4",
        "blanes-moan4+heun3",
        "yoshida4",
        "suzuki4",
        "strang",
    }
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert main(argv) == 0  # second time: the reference comes from the cache
    assert json.loads(capsys.readouterr().out)["scenes"][0]["reference"]["from_cache"]


@pytest.mark.parametrize(
    ("extra", "needle"),
    [
        (["--scene", "medium"], "unknown scene"),
        (["--amplitude", "2"], "--amplitude"),
        (["--amplitude", "nan um"], "--amplitude"),
        (["--duration", "nan ms"], "--duration"),
        (["--direction", "up"], "--direction"),
        (["--plot", "out.pdf"], "--plot"),
    ],
)
def test_cli_bad_input_is_one_line(
    extra: list[str], needle: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["accuracy", "--quick", *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and needle in err and "error" in err


def test_simulate_cli_stores_error_indicators(tmp_path: Path) -> None:
    out = tmp_path / "run.h5"
    argv = ["simulate", "--direction", "ltr", "--amplitude", "4um", "--duration", "1 ms"]
    assert main([*argv, "--out", str(out)]) == 0
    with h5py.File(out, "r") as f:
        attrs = dict(f["simulation"].attrs)
    assert attrs["integrator"] == "blanes-moan4" and int(attrs["order"]) == 4
    assert 0 < float(attrs["dt_s"]) <= 2e-6
    assert 0 < float(attrs["error_estimate_rel"]) < 1e-3
    assert 0.0 < float(attrs["work_not_in_chain_rel"]) < 1.0  # dissipated by the damping
    assert "energy_residual_rel" not in attrs


def test_timed_wall_excludes_loading_the_kernel(monkeypatch: pytest.MonkeyPatch) -> None:
    """The first timed point of ``biafc accuracy`` in a new process used to include loading (or
    compiling) the kernel: 0.97 s on a point that runs in 0.03 s."""
    from sim_backend.dem import accuracy, kernel_cache

    loaded = {"yes": False}

    def fn() -> str:
        import time

        time.sleep(0.0 if loaded["yes"] else 0.5)  # the first call loads the kernel
        loaded["yes"] = True
        return "ran"

    monkeypatch.setattr(kernel_cache, "kernel_loaded", lambda: loaded["yes"])
    out, wall = accuracy._timed_best(fn)
    assert out == "ran" and wall < 0.25
