"""The stability certificate from half a step (issue 18: the stability check under 5 % of a run):
the half map is the step map's first half, the certificate never calls an unstable step stable,
the certified stiffnesses form an interval from 0, and a chain's first check is one certificate,
with no grid scan and no compiled code loaded."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from instruments.burst import Burst
from sim_backend import dem
from sim_backend.dem import step_limit, verdict_store
from sim_backend.dem.kernel import drift_coefficients
from sim_backend.dem.simulation import INTEGRATORS, block_modes
from sim_backend.dem.stability_certificate import (
    _gram,
    _half_band,
    _rotations,
    certified,
    half_map,
    half_stages,
)
from tests.dem.compiled_reference import stages
from tests.dem.step_map import STABLE, stability_codes

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def default() -> dem.Chain:
    return dem.build_chain(dem.default_chain_spec())


@pytest.fixture(scope="module")
def not_shipped() -> dem.Chain:
    """A chain whose verdicts do not ship (the default with another preload)."""
    return dem.build_chain(dem.load_chain_with_settings(None, ["preload=6 N"]))


def _window(chain: dem.Chain) -> Any:
    (win,) = step_limit._windows(chain)
    return win


def _w_top(chain: dem.Chain) -> float:
    return float(block_modes(chain).omega.max())


@pytest.mark.parametrize("name", sorted(INTEGRATORS))
def test_the_half_stages_are_half_the_splitting(name: str) -> None:
    """Drift, kick, drift, ...: the whole splitting's first half, the middle stage halved."""
    _, a_w, b_w = INTEGRATORS[name]
    drifts, kicks = half_stages(a_w, b_w)
    whole = [w for pair in zip(a_w, (*b_w, None), strict=True) for w in pair if w is not None]
    pairs = zip(drifts, (*kicks, None), strict=False)  # drifts: as many as kicks, or one more
    half = [w for pair in pairs for w in pair if w is not None]
    mid = len(whole) // 2
    assert half == [*whole[:mid], 0.5 * whole[mid]]
    assert math.fsum(drifts) == pytest.approx(0.5, abs=1e-15)
    assert math.fsum(kicks) == pytest.approx(0.5, abs=1e-15)


def test_the_drifts_are_the_kernels_undamped_drifts(default: dem.Chain) -> None:
    om = block_modes(default).omega.ravel()
    t = np.array([0.3e-6, -1.1e-6, 2.9e-6])
    got = _rotations(om, t)
    for i, ti in enumerate(t):
        ref = drift_coefficients(om, np.zeros_like(om), float(ti))
        assert np.allclose(got[i], ref, rtol=1e-15, atol=0)


def test_a_splitting_that_is_not_palindromic_has_no_half() -> None:
    with pytest.raises(ValueError, match="not palindromic"):
        half_stages((0.2, 0.8), (1.0,))


@pytest.mark.parametrize("name", sorted(INTEGRATORS))
def test_the_half_map_gives_the_compiled_step_maps_blocks(default: dem.Chain, name: str) -> None:
    """``A = Xd^T Xa + Xb^T Xc`` and ``B = 2 Xb^T Xd`` (M = R X^-1 R X) are the position blocks of
    the whole step that the compiled map builds stage by stage; X is symplectic."""
    win = _window(default)
    _, a_w, b_w = INTEGRATORS[name]
    h = 0.6 * math.pi / _w_top(default)
    k = step_limit.contact_stiffness_N_per_m(default, 4 * default.delta0_m)
    Q, P = half_map(win.phi, win.omega, win.left, win.right, a_w, b_w, h, k)
    D = Q.shape[0]
    Xa, Xb, Xc, Xd = Q[:, :D], Q[:, D:], P[:, :D], P[:, D:]
    A, B = step_limit._position_blocks(win, name, h, np.array([k]))
    assert np.abs(Xd.T @ Xa + Xb.T @ Xc - A[0]).max() <= 1e-13 * np.abs(A[0]).max()
    assert np.abs(2 * Xb.T @ Xd - B[0]).max() <= 1e-13 * np.abs(B[0]).max()
    # the certificate's products, summed on the band, are the dense ones
    Qb, Pb = _half_band(win.phi, win.omega, win.left, win.right, a_w, b_w, h, k)
    K = Qb.shape[2]
    for band, dense in ((_gram(Qb[..., :K], Qb[..., K:]), Xa @ Xb.T),
                        (_gram(Pb[..., :K], Pb[..., K:]), Xc @ Xd.T)):  # fmt: skip
        assert np.abs(band - dense).max() <= 1e-13 * np.abs(dense).max()
    X = np.vstack([Q, P])
    J = np.block([[np.zeros((D, D)), np.eye(D)], [-np.eye(D), np.zeros((D, D))]])
    scale = np.abs(X).max() ** 2
    assert np.abs(X.T @ J @ X - J).max() <= 1e-12 * scale


def test_strangs_certificate_factors_as_the_docstring_says(default: dem.Chain) -> None:
    """Strang: ``Xa Xb^T`` does not depend on the stiffness, ``-Xc Xd^T = Y T Z`` (the proof that
    its certified stiffnesses are an interval)."""
    win = _window(default)
    _, a_w, b_w = INTEGRATORS["strang"]
    h = 0.7 * math.pi / _w_top(default)
    om = win.omega.ravel()
    n, K = win.phi.shape
    Phi = np.zeros((n, n * K))
    for i in range(n):
        Phi[i, i * K : (i + 1) * K] = win.phi[i]
    kc = step_limit._contact_matrix(n, 1.0, win.left, win.right)
    G = Phi.T @ kc @ Phi
    th = 0.5 * om * h
    rigid = om == 0.0
    wsafe = np.where(rigid, 1.0, om)
    # the diagonals W S / C, C S / W, W C / S, with their limits for the rigid translations
    y0 = np.where(rigid, 0.0, om * np.tan(th))
    t0 = np.where(rigid, 0.5 * h, np.cos(th) * np.sin(th) / wsafe)
    z0 = np.where(rigid, 2.0 / h, om / np.where(rigid, 1.0, np.tan(th)))
    products = []
    for k in (0.3e6, 3e6, 30e6):
        Q, P = half_map(win.phi, win.omega, win.left, win.right, a_w, b_w, h, k)
        D = Q.shape[0]
        products.append(Q[:, :D] @ Q[:, D:].T)
        kappa = 0.5 * k * h
        Y = np.diag(y0) + kappa * G
        Z = np.diag(z0) - kappa * G
        got = -(P[:, :D] @ P[:, D:].T)
        assert np.allclose(got, Y @ np.diag(t0) @ Z, rtol=0, atol=1e-10 * np.abs(got).max())
    assert np.allclose(products[0], products[2], rtol=0, atol=1e-14 * np.abs(products[0]).max())


def _codes(win: Any, name: str, h: float, ks: np.ndarray) -> np.ndarray:
    coef, idx, kick = stages(win, name, h)
    codes, _, _ = stability_codes(win.phi, coef, idx, kick, ks, win.left, win.right,
                                  step_limit._C_TOL)  # fmt: skip
    return codes


def _chains() -> dict[str, dem.Chain]:
    base = dem.default_chain_spec()
    stiff = {"contact_stiffness_factor": 100.0}
    return {
        "default": dem.build_chain(base),
        "preload 0.5 N": dem.build_chain(base.model_copy(update={"preload": 0.5})),
        "contact x100": dem.build_chain(base.model_copy(update=stiff)),
        "13 cylinders, 2 resonators": dem.build_chain(
            base.model_copy(update={"n_cylinders": 13, "n_modes": 2})
        ),
    }


@pytest.mark.parametrize("name", sorted(INTEGRATORS))
def test_certified_is_stable_and_the_certified_stiffnesses_are_an_interval(name: str) -> None:
    """A sample of the measurement in the module docstring: across the small-step regime and a
    stiffness ladder from 1 % to 1000x the preload's, every certified stiffness is stable by the
    compiled test, and none is certified above one that is not."""
    _, a_w, b_w = INTEGRATORS[name]
    certified_points = 0
    for label, chain in _chains().items():
        win = _window(chain)
        k0 = step_limit.contact_stiffness_N_per_m(chain, chain.delta0_m)
        ks = np.geomspace(1e-2 * k0, 1e3 * k0, 40)
        for f in (0.1, 0.45, 0.7, step_limit.CERTIFIED_STEP_FRACTION):
            h = f * math.pi / _w_top(chain)
            cert = np.array([certified(win.phi, win.omega, win.left, win.right, a_w, b_w, h, k)
                             for k in ks])  # fmt: skip
            codes = _codes(win, name, h, ks)
            assert np.all(codes[cert] == STABLE), (label, f)
            first_off = int(np.argmin(cert)) if not cert.all() else ks.size
            assert not cert[first_off:].any(), (label, f)
            certified_points += int(cert.sum())
    assert certified_points > 0


def test_near_the_regimes_edge_the_grid_decides() -> None:
    """At 0.99 of the small-step regime, yoshida6 on a short chain with 2 resonators is stable at
    small and large stiffnesses with an unstable band between them, and the certificate holds at
    one stiffness above the band: taken as covering the band, it would pass an unstable step.
    ``_certified`` leaves such steps to the grid (``CERTIFIED_STEP_FRACTION``)."""
    spec = dem.default_chain_spec().model_copy(update={"n_cylinders": 13, "n_modes": 2})
    chain = dem.build_chain(spec)
    win = _window(chain)
    _, a_w, b_w = INTEGRATORS["yoshida6"]
    h = 0.99 * math.pi / _w_top(chain)
    k0 = step_limit.contact_stiffness_N_per_m(chain, chain.delta0_m)
    ks = np.geomspace(1e-2 * k0, 1e3 * k0, 400)
    cert = np.array([certified(win.phi, win.omega, win.left, win.right, a_w, b_w, h, k)
                     for k in ks])  # fmt: skip
    stable = _codes(win, "yoshida6", h, ks) == STABLE
    first_unstable = int(np.argmin(stable))
    above = first_unstable + int(np.argmax(cert[first_unstable:]))
    assert cert[above] and above > first_unstable  # certified above an unstable stiffness
    overlap = (ks[above] / (1.5 * chain.beta_c)) ** 2
    assert step_limit.contact_stiffness_N_per_m(chain, overlap) == pytest.approx(ks[above])
    assert not step_limit._certified(chain, "yoshida6", h, overlap)


def test_the_certificate_refuses_a_step_past_the_small_step_regime(default: dem.Chain) -> None:
    win = _window(default)
    _, a_w, b_w = INTEGRATORS["blanes-moan4"]
    k = step_limit.contact_stiffness_N_per_m(default, default.delta0_m)
    h_pi = math.pi / _w_top(default)
    assert certified(win.phi, win.omega, win.left, win.right, a_w, b_w, 0.99 * h_pi, k)
    assert not certified(win.phi, win.omega, win.left, win.right, a_w, b_w, 1.0 * h_pi, k)
    assert not certified(win.phi, win.omega, win.left, win.right, a_w, b_w, 0.0, k)


def _wrap(certify: Any, seen: dict[str, list[Any]]) -> Any:
    def cert(chain: dem.Chain, integrator: str, h: float, overlap: float) -> bool:
        ok = bool(certify(chain, integrator, h, overlap))
        seen["certificates"].append((h, overlap, ok))
        return ok

    return cert


def _spy(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> dict[str, list[Any]]:
    """An empty user cache and memory; the certificates and grid scans from now on."""
    monkeypatch.setenv("BIAFC_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(step_limit, "_RANGE_CACHE", {})
    monkeypatch.setattr(step_limit, "_STABLE_CACHE", {})
    seen: dict[str, list[Any]] = {"certificates": [], "grid": []}
    certified_ = step_limit._certified
    stable_many = step_limit._stable_many

    def grid(chain: dem.Chain, integrator: str, h: float, overlaps: Any, **kw: Any) -> list[bool]:
        seen["grid"].extend(overlaps)
        return stable_many(chain, integrator, h, overlaps, **kw)

    monkeypatch.setattr(step_limit, "_certified", _wrap(certified_, seen))
    monkeypatch.setattr(step_limit, "_stable_many", grid)
    return seen


def test_a_chains_first_check_is_one_certificate_and_no_grid(
    not_shipped: dem.Chain, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    seen = _spy(monkeypatch, tmp_path)
    chain = not_shipped
    d = dem.Drive("ltr", "displacement", 3e-6, burst=Burst(8.92e3))
    step_limit.check_step(chain, "blanes-moan4", 5e-6, [d])
    assert len(seen["certificates"]) == 1 and seen["certificates"][0][2]
    assert seen["grid"] == []
    # the verdict covers the grid up to the certified point, CERTIFIED_AHEAD grid points above
    # the one this drive needs, and lands in the user cache
    key = step_limit.range_key(chain, "blanes-moan4", 5e-6)
    v = step_limit._RANGE_CACHE[key]
    top = step_limit._grid_at_or_above(chain.delta0_m, step_limit.reference_overlap_m(chain, [d]))
    ahead = top * step_limit.RANGE_RATIO**step_limit.CERTIFIED_AHEAD
    assert v.stable_to_m == seen["certificates"][0][1] == pytest.approx(ahead, rel=1e-12)
    assert v.stable_to_m == step_limit._grid_at_or_above(chain.delta0_m, v.stable_to_m)
    verdict_store.flush()
    stored = json.loads((tmp_path / "step-stability.json").read_text())[key]
    assert stored[1] == v.stable_to_m
    # a smaller drive, and one three times larger, ask nothing more
    for a in (1e-6, 9e-6):
        step_limit.check_step(chain, "blanes-moan4", 5e-6, [dem.Drive("ltr", "displacement", a,
                              burst=Burst(8.92e3))])  # fmt: skip
    assert len(seen["certificates"]) == 1 and seen["grid"] == []


def test_where_the_certificate_fails_ahead_it_is_tried_where_needed(
    not_shipped: dem.Chain, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    real = step_limit._certified
    seen = _spy(monkeypatch, tmp_path)
    need = 4 * not_shipped.delta0_m

    def fails_ahead(chain: dem.Chain, integrator: str, h: float, overlap: float) -> bool:
        return overlap < 2 * need and real(chain, integrator, h, overlap)

    monkeypatch.setattr(step_limit, "_certified", _wrap(fails_ahead, seen))
    assert step_limit.stable_up_to(not_shipped, "blanes-moan4", 5e-6, need)
    assert [ok for _, _, ok in seen["certificates"]] == [False, True]
    assert seen["grid"] == []
    top = step_limit._grid_at_or_above(not_shipped.delta0_m, need)
    assert step_limit._RANGE_CACHE[step_limit.range_key(not_shipped, "blanes-moan4", 5e-6)
                                   ].stable_to_m == top  # fmt: skip


@pytest.mark.parametrize("factor", [1.0, 100.0])
def test_with_or_without_the_certificate_the_verdicts_agree(
    factor: float, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """Across steps up to and past the small-step regime (where the certificate does not hold
    and the grid decides), and with contacts 100x stiffer (certificates that fail inside the
    regime), ``stable_up_to`` says what the grid alone says."""
    seen = _spy(monkeypatch, tmp_path)
    spec = dem.default_chain_spec().model_copy(update={"contact_stiffness_factor": factor})
    chain = dem.build_chain(spec)
    h_pi = math.pi / _w_top(chain)
    overlap = 4 * chain.delta0_m
    steps = [f * h_pi for f in (0.3, 0.6, 0.9, 0.99, 1.1, 1.6, 2.5)]
    with_cert = [step_limit.stable_up_to(chain, "blanes-moan4", h, overlap) for h in steps]
    monkeypatch.setattr(step_limit, "_RANGE_CACHE", {})
    monkeypatch.setattr(step_limit, "_certified", lambda *args: False)
    grid_only = [step_limit.stable_up_to(chain, "blanes-moan4", h, overlap) for h in steps]
    assert with_cert == grid_only
    oks = [ok for _, _, ok in seen["certificates"]]
    assert any(oks)
    if factor > 1.0:
        assert not all(oks)  # some certificates failed and the grid decided
    assert not all(grid_only)  # the sample reaches unstable steps


def test_a_fresh_process_checks_without_loading_compiled_code(tmp_path: Path) -> None:
    """``check_step`` on a chain that does not ship, in a new process with an empty cache folder:
    the verdict is certified and stored, and no compiled code is loaded or compiled."""
    probe = """
import json, sys
from instruments.burst import Burst
from sim_backend import dem
from sim_backend.dem import step_limit
chain = dem.build_chain(dem.load_chain_with_settings(None, ["preload=6 N"]))
d = dem.Drive("ltr", "displacement", 3e-6, burst=Burst(8.92e3))
step_limit.check_step(chain, "blanes-moan4", 5e-6, [d])
import numba
compiled = sorted(n for m in list(sys.modules.values())
                  if getattr(m, "__name__", "").startswith("sim_backend")
                  for n, o in vars(m).items()
                  if isinstance(o, numba.core.registry.CPUDispatcher) and o.signatures)
print(json.dumps({"compiled": compiled}))
"""
    env = dict(os.environ, BIAFC_CACHE_DIR=str(tmp_path))
    out = subprocess.run([sys.executable, "-c", probe], cwd=ROOT, env=env, capture_output=True,
                         text=True, check=True, timeout=300)  # fmt: skip
    assert json.loads(out.stdout.strip().splitlines()[-1]) == {"compiled": []}
    # the background write finished before the process ended
    stored = json.loads((tmp_path / "step-stability.json").read_text())
    assert len(stored) == 1
