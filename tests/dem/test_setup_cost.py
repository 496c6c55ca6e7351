"""No hidden seconds in setting up a chain (issue 18): the modes in closed form without BLAS,
one BLAS thread in the small linear algebra, the step-stability check once per chain and step."""

from __future__ import annotations

import math
import types
import weakref

import numpy as np
import pytest
import scipy.linalg
from threadpoolctl import threadpool_limits

from instruments.burst import Burst
from sim_backend import dem
from sim_backend.dem import beam, simulation, step_limit
from sim_backend.dem.material import FUSED_QUARTZ
from sim_backend.dem.threads import blas_threads
from tests.dem.compiled_reference import stages

D = 0.0136


def _expm_det_and_numer(lam: float, s: float, r: float) -> tuple[float, float]:
    """The previous path: scipy's expm of the 4x4 transfer matrix."""
    a = np.array([[0, 1, 0, s], [0, 0, 1, 0], [0, -lam * r, 0, -1], [-lam, 0, 0, 0]], float)
    t = scipy.linalg.expm(a)
    return t[2, 2] * t[3, 3] - t[2, 3] * t[3, 2], -(t[2, 2] * t[3, 0] - t[3, 2] * t[2, 0])


@pytest.mark.parametrize("theory", ["timoshenko", "euler-bernoulli"])
def test_closed_form_transfer_matrix_is_expm(theory: str) -> None:
    _, s, r, _ = beam.section_parameters(0.09, D, FUSED_QUARTZ, theory)
    # up to beta = 12, and past the second spectrum of a stubby beam (lambda r s > 1)
    for lam in (1e-3, 0.3, 12.0, 500.0, 2.0e4, 4.0 / max(r * s, 1e-30) if s else 3e4):
        with threadpool_limits(1, user_api="blas"):
            ref = scipy.linalg.expm(
                np.array([[0, 1, 0, s], [0, 0, 1, 0], [0, -lam * r, 0, -1], [-lam, 0, 0, 0]])
            )
        got = beam._transfer(np.array(lam), np.array(s), np.array(r))
        assert np.abs(got - ref).max() <= 1e-12 * np.abs(ref).max()


def test_modes_agree_with_the_expm_path_and_masses_with_a_40_digit_reference() -> None:
    mpmath = pytest.importorskip("mpmath")
    mpmath.mp.dps = 40
    lengths = (0.09, 0.1, 0.11)
    new = beam.cylinder_modes(list(lengths), D, [FUSED_QUARTZ] * 3, 3)
    for L, modes in zip(lengths, new, strict=True):
        m_half, s, r, lam_w2 = beam.section_parameters(L, D, FUSED_QUARTZ, "timoshenko")
        for w, m_j in zip(modes.omega_rad_s, modes.modal_mass_kg, strict=True):
            lam0 = lam_w2 * w**2
            # frequencies: the root of the previous (expm) determinant to 1e-12
            d_lo = _expm_det_and_numer(lam0 * (1 - 1e-12), s, r)[0]
            d_hi = _expm_det_and_numer(lam0 * (1 + 1e-12), s, r)[0]
            assert (d_lo < 0) != (d_hi < 0)

            def det(x: object, s: float = s, r: float = r) -> object:
                a = mpmath.matrix([[0, 1, 0, s], [0, 0, 1, 0], [0, -x * r, 0, -1], [-x, 0, 0, 0]])
                t = mpmath.expm(a)
                return t[2, 2] * t[3, 3] - t[2, 3] * t[3, 2], -(
                    t[2, 2] * t[3, 0] - t[3, 2] * t[2, 0]
                )

            lam = mpmath.findroot(lambda x: det(x)[0], mpmath.mpf(lam0))
            ddet = mpmath.diff(lambda x: det(x)[0], lam)
            m_exact = float(-det(lam)[1] / (ddet * lam**2) * 2 * m_half)
            assert math.sqrt(float(lam) / lam_w2) == pytest.approx(w, rel=1e-13)
            # the effective masses to 1e-11 (the expm path's difference quotient: 1e-9 to 4e-9)
            assert m_j == pytest.approx(m_exact, rel=1e-11)


def test_euler_bernoulli_six_modes_match_the_cantilever_formulas() -> None:
    """Roots of 1 + cos b cosh b = 0 and effective-mass fractions 4 sigma^2 / b^2 (the expm path
    was 2e-4 off at the sixth mode)."""
    from scipy.optimize import brentq

    modes = beam.beam_modes(0.1, D, FUSED_QUARTZ, 6, "euler-bernoulli")
    _, _, _, lam_w2 = beam.section_parameters(0.1, D, FUSED_QUARTZ, "euler-bernoulli")
    beta = (lam_w2 * modes.omega_rad_s**2) ** 0.25
    for j, b in enumerate(beta):
        guess = (j + 0.5) * math.pi
        exact = brentq(lambda x: np.cos(x) + 1.0 / np.cosh(x), guess - 0.5, guess + 0.5, xtol=1e-15)
        assert b == pytest.approx(exact, rel=1e-9)
        sigma = (math.sinh(exact) - math.sin(exact)) / (math.cosh(exact) + math.cos(exact))
        frac = modes.modal_mass_kg[j] / modes.mass_kg
        assert frac == pytest.approx(4 * sigma**2 / exact**2, rel=1e-8)


def test_build_chain_calls_no_dense_linear_algebra(monkeypatch: pytest.MonkeyPatch) -> None:
    """build_chain reaches no BLAS/LAPACK routine (numpy.linalg, scipy.linalg), so no BLAS
    thread pool wakes up: the cost that took a minute on a loaded two-core host."""

    def refuse(*args: object, **kwargs: object) -> None:
        raise AssertionError("build_chain called a dense linear-algebra routine")

    import sim_backend.dem as dem_pkg

    for mod in (np.linalg, scipy.linalg):
        for name in dir(mod):
            if not name.startswith("_") and callable(getattr(mod, name)):
                monkeypatch.setattr(mod, name, refuse, raising=False)
    for name in dir(dem_pkg):  # names imported into the model's modules
        module = getattr(dem_pkg, name)
        if isinstance(module, types.ModuleType):
            for attr, value in vars(module).items():
                owner = getattr(value, "__module__", "") or ""
                if callable(value) and owner.startswith(("scipy.linalg", "numpy.linalg")):
                    monkeypatch.setattr(module, attr, refuse)
    spec = dem.default_chain_spec().model_copy(update={"n_modes": 4})  # not built elsewhere
    beam._modes_cached.cache_clear()
    chain = dem.build_chain(spec)
    assert chain.omega_res_rad_s.shape == (31, 4)


def test_small_linear_algebra_runs_on_one_blas_thread(
    chain: dem.Chain, monkeypatch: pytest.MonkeyPatch
) -> None:
    seen: list[list[int]] = []
    eigh, eigvals = simulation.eigh, np.linalg.eigvals

    def eigh_spy(*args: object, **kwargs: object) -> object:
        seen.append(blas_threads())
        return eigh(*args, **kwargs)

    def eigvals_spy(*args: object, **kwargs: object) -> object:
        seen.append(blas_threads())
        return eigvals(*args, **kwargs)

    monkeypatch.setattr(simulation, "eigh", eigh_spy)
    monkeypatch.setattr(np.linalg, "eigvals", eigvals_spy)
    monkeypatch.setattr(simulation, "_MODES", weakref.WeakKeyDictionary())  # solve them again
    with threadpool_limits(2, user_api="blas"):  # the user's (or the default) setting
        simulation.block_modes(chain)
        step_limit.spectral_radius(chain, "strang", 1e-6, chain.delta0_m)
        after = blas_threads()
    assert seen and all(n == [1] * len(n) for n in seen if n)
    assert all(n == 2 for n in after)  # restored


def test_stability_check_runs_once_per_chain_and_step(
    undamped: dem.Chain, monkeypatch: pytest.MonkeyPatch, tmp_path: object
) -> None:
    monkeypatch.setenv("BIAFC_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(step_limit, "_RANGE_CACHE", {}, raising=False)
    monkeypatch.setattr(step_limit, "_STABLE_CACHE", {})
    calls: list[float] = []  # one entry per overlap whose stability was computed
    stable_many = step_limit._stable_many

    def counting(chain: dem.Chain, integrator: str, h: float, overlaps: list[float]) -> list[bool]:
        calls.extend(overlaps)
        return stable_many(chain, integrator, h, overlaps)

    certified = step_limit._certified

    def counting_certificates(chain: dem.Chain, integrator: str, h: float, overlap: float) -> bool:
        calls.append(overlap)
        return certified(chain, integrator, h, overlap)

    monkeypatch.setattr(step_limit, "_stable_many", counting)
    monkeypatch.setattr(step_limit, "_certified", counting_certificates)
    amplitudes = undamped.delta0_m * np.geomspace(0.05, 3.0, 24)
    drives = [dem.Drive("ltr", "displacement", float(a), burst=Burst(8.92e3)) for a in amplitudes]
    for d in drives:  # one key each, as the simulated bench's DEM runs are
        step_limit.check_step(undamped, "blanes-moan4", 4e-6, [d])
    first = len(calls)
    assert 0 < first <= 14  # one scan up to the largest overlap, not two eigenproblems per key
    for d in drives:
        step_limit.check_step(undamped, "blanes-moan4", 4e-6, [d])
    assert len(calls) == first
    # a new process (empty memory) reads the verdict from the user's cache folder
    monkeypatch.setattr(step_limit, "_RANGE_CACHE", {}, raising=False)
    step_limit.check_step(undamped, "blanes-moan4", 4e-6, drives[-1:])
    assert len(calls) == first


def test_range_check_refuses_what_the_two_point_check_refuses(undamped: dem.Chain) -> None:
    lim = step_limit.largest_stable_step(undamped, "strang")
    for h in (0.98 * lim.h_max_s, 1.05 * lim.h_max_s):
        for ov in (undamped.delta0_m, 4 * undamped.delta0_m):
            if not step_limit.is_stable(undamped, "strang", h, ov):
                assert not step_limit.stable_up_to(undamped, "strang", h, ov)
    assert step_limit.stable_up_to(undamped, "strang", 0.98 * lim.h_max_s, 4 * undamped.delta0_m)


def _dense_step_map(chain: dem.Chain, integrator: str, h: float, k: float) -> np.ndarray:
    """The [2D, 2D] one-step map from dense matrices: Phi^T Kc Phi and 2x2 rotations per mode
    (written here from the splitting's definition, independently of step_limit's fast path)."""
    modes = simulation.block_modes(chain)
    _, a_w, b_w = simulation.INTEGRATORS[integrator]
    n, K = modes.phi0.shape
    D = n * K
    Phi = np.zeros((n, D))
    for i in range(n):
        Phi[i, i * K : (i + 1) * K] = modes.phi0[i]
    kc = np.zeros((n, n))
    for j in range(n + 1):  # contacts: wall | 1 | 2 | ... | n | wall
        left, right = j - 1, j
        for a in (left, right):
            for b in (left, right):
                if 0 <= a < n and 0 <= b < n and (chain.far_end == "wall" or j < n):
                    kc[a, b] += k if a == b else -k
    stiff = Phi.T @ kc @ Phi
    om = modes.omega.ravel()
    M = np.eye(2 * D)

    def drift(t: float) -> np.ndarray:
        c = np.cos(om * t)
        s = np.where(om > 0, np.sin(om * t) / np.where(om > 0, om, 1.0), t)
        return np.block([[np.diag(c), np.diag(s)], [np.diag(-om * np.sin(om * t)), np.diag(c)]])

    for stage, b in enumerate(b_w):
        M = drift(a_w[stage] * h) @ M
        M = np.block([[np.eye(D), np.zeros((D, D))], [-b * h * stiff, np.eye(D)]]) @ M
    return drift(a_w[-1] * h) @ M


@pytest.mark.parametrize("integrator", ["blanes-moan4", "strang", "yoshida4"])
def test_reduced_spectral_radius_equals_the_dense_eigenvalues(
    undamped: dem.Chain, integrator: str
) -> None:
    """The position-block reduction (size D, symmetric when B > 0) gives the dense map's
    spectral radius, stable and unstable steps alike, on both of its paths (a 12-cylinder
    chain, so that the dense reference is cheap)."""
    undamped = dem.build_chain(undamped.spec.model_copy(update={"n_cylinders": 12}))
    h_top = math.pi / float(simulation.block_modes(undamped).omega.max())
    paths, verdicts = set(), set()
    for hf in (0.3, 0.9, 1.3, 2.0, 4.0):
        for ov in (1.0, 4.0, 16.0):
            h = hf * h_top
            k = step_limit.contact_stiffness_N_per_m(undamped, ov * undamped.delta0_m)
            dense = float(
                np.abs(np.linalg.eigvals(_dense_step_map(undamped, integrator, h, k))).max()
            )
            got = step_limit.spectral_radius(undamped, integrator, h, ov * undamped.delta0_m)
            assert got == pytest.approx(dense, rel=1e-9, abs=1e-9)
            stable = step_limit._stable_at(undamped, integrator, h, ov * undamped.delta0_m)
            assert stable == (dense <= 1.0 + step_limit.STABILITY_TOL)
            verdicts.add(stable)
            Q, _ = step_limit._step_map(step_limit._windows(undamped)[0], integrator, h, k)
            B = Q[:, Q.shape[0] :]
            paths.add(bool(np.all(np.linalg.eigvalsh(0.5 * (B + B.T)) > 0)))
    assert paths == {True, False}  # the symmetric and the general path both ran
    assert verdicts == {True, False}


def test_spectral_radius_solves_one_position_block_and_reuses_the_block_modes(
    undamped: dem.Chain, monkeypatch: pytest.MonkeyPatch
) -> None:
    """No eigenvalue problem of the whole [2D, 2D] map (D = 124 here), and the chain's block
    modes computed once for a scan, not once per overlap."""
    sizes: list[int] = []
    calls = {"block_modes": 0}
    eigvals, eigvalsh, block_modes = np.linalg.eigvals, np.linalg.eigvalsh, simulation.block_modes

    def eigvals_spy(a: np.ndarray) -> object:
        sizes.append(a.shape[0])
        return eigvals(a)

    def eigvalsh_spy(a: np.ndarray) -> object:
        sizes.append(a.shape[0])
        return eigvalsh(a)

    def block_modes_spy(chain: dem.Chain) -> object:
        calls["block_modes"] += 1
        return block_modes(chain)

    monkeypatch.setattr(np.linalg, "eigvals", eigvals_spy)
    monkeypatch.setattr(np.linalg, "eigvalsh", eigvalsh_spy)
    monkeypatch.setattr(simulation, "block_modes", block_modes_spy)
    monkeypatch.setattr(step_limit, "_WINDOW_CACHE", {})
    for ov in (1.0, 2.0, 4.0):
        for h in (1e-6, 4e-6, 12e-6):
            step_limit.spectral_radius(undamped, "blanes-moan4", h, ov * undamped.delta0_m)
    D = undamped.n * (undamped.n_modes + 1)
    assert sizes and max(sizes) == D
    assert calls["block_modes"] == 1


def test_importing_the_model_leaves_scipy_solvers_unimported() -> None:
    """``import sim_backend.dem`` (every command that runs the model pays it) loads no
    scipy.interpolate, scipy.optimize, scipy.special or scipy.linalg: 0.3 s to 1 s of imports
    that only designing a chain, computing bands or the first simulation needs."""
    import subprocess
    import sys

    code = (
        "import sys, sim_backend.dem; "
        "print(sorted(m for m in ('scipy.interpolate', 'scipy.optimize', 'scipy.special', "
        "'scipy.linalg') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_one_blas_thread_limits_scipys_blas_loaded_after_the_model() -> None:
    """scipy.linalg (and the BLAS its wheels bundle) is imported on the model's first linear
    algebra, not with sim_backend.dem: the limit must cover it all the same (in a fresh process,
    where nothing imported scipy.linalg before; it ran scipy's BLAS on 2 threads)."""
    import json
    import subprocess
    import sys

    code = (
        "import json\n"
        "from sim_backend import dem\n"
        "from sim_backend.dem import simulation\n"
        "from sim_backend.dem.threads import blas_threads\n"
        "from threadpoolctl import threadpool_limits\n"
        "seen = []\n"
        "eigh = simulation.eigh\n"
        "def spy(a, b):\n"
        "    seen.append(blas_threads())\n"
        "    return eigh(a, b)\n"
        "simulation.eigh = spy\n"
        "chain = dem.build_chain(dem.default_chain_spec())\n"
        "with threadpool_limits(2, user_api='blas'):\n"
        "    simulation.block_modes(chain)\n"
        "print(json.dumps(seen))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    seen = json.loads(out.stdout)
    assert seen and all(n == [1] * len(n) and n for n in seen), seen


@pytest.mark.parametrize("integrator", ["blanes-moan4", "strang", "yoshida6"])
def test_banded_position_blocks_equal_the_numpy_step_map(
    undamped: dem.Chain, integrator: str
) -> None:
    """The compiled kernel (the band a column reaches, all stiffnesses at once) gives the position
    rows of the numpy map, on the whole chain and on windows without end contacts, of one
    cylinder, and of two."""
    whole = step_limit._windows(undamped)[0]
    windows = [
        whole,
        step_limit._Window(whole.phi[:7], whole.omega[:7], False, False),
        step_limit._Window(whole.phi[3:5], whole.omega[3:5], False, True),
        step_limit._Window(whole.phi[:1], whole.omega[:1], True, True),
    ]
    h = 3.0e-6
    ks = np.array([step_limit.contact_stiffness_N_per_m(undamped, f * undamped.delta0_m)
                   for f in (0.5, 1.0, 7.0)])  # fmt: skip
    for win in windows:
        A, B = step_limit._position_blocks(win, integrator, h, ks)
        for o, k in enumerate(ks):
            Q, _ = step_limit._step_map(win, integrator, h, float(k))
            D = Q.shape[0]
            scale = np.abs(Q).max()
            assert np.abs(A[o] - Q[:, :D]).max() <= 1e-13 * scale
            assert np.abs(B[o] - Q[:, D:]).max() <= 1e-13 * scale


def test_scan_verdicts_equal_the_dense_eigenvalues_on_the_default_chain(
    undamped: dem.Chain,
) -> None:
    """The verdicts of a batched scan (the 31-cylinder chain, D = 124, every overlap in one
    compiled call) against the dense [2D, 2D] map's eigenvalues: stable steps, the narrow
    unstable band of blanes-moan4 near 7.4 us and the steps beyond its limit."""
    overlaps = [f * undamped.delta0_m for f in (1.0, 1.25**4, 1.25**7, 16.0)]
    verdicts = set()
    for h in (3.3333333333333337e-06, 6.5e-6, 7.4e-6, 8.1e-6, 9.0e-6):
        got = step_limit._stable_many(undamped, "blanes-moan4", h, overlaps)
        for ov, stable in zip(overlaps, got, strict=True):
            k = step_limit.contact_stiffness_N_per_m(undamped, ov)
            dense = np.abs(np.linalg.eigvals(_dense_step_map(undamped, "blanes-moan4", h, k)))
            assert stable == (dense.max() <= 1.0 + step_limit.STABILITY_TOL), (h, ov / 1e-6)
            verdicts.add(stable)
    assert verdicts == {True, False}


def _compiled_window_verdicts(
    win: step_limit._Window, integrator: str, h: float, ks: np.ndarray, small_step: bool
) -> list[bool]:
    """The verdicts of the compiled map and test (``step_map.stability_codes``, built stage by
    stage on the band), the eigenvalues of its blocks where a factorisation failed: the path the
    check took before the half-step blocks, kept as an independent implementation."""
    from tests.dem.step_map import STABLE, UNDECIDED, stability_codes

    coef, idx, kick = stages(win, integrator, h)
    codes, A, Bs = stability_codes(win.phi, coef, idx, kick, ks, win.left, win.right,
                                   step_limit._C_TOL, small_step)  # fmt: skip
    return [
        bool(code == STABLE)
        or (code == UNDECIDED and step_limit._radius_from_blocks(A[o], Bs[o]) <= 1 + 1e-6)
        for o, code in enumerate(codes.tolist())
    ]


@pytest.mark.parametrize("integrator", ["blanes-moan4", "yoshida6"])
def test_half_step_verdicts_equal_the_compiled_ones(undamped: dem.Chain, integrator: str) -> None:
    """The blocks from half a step's map (numpy, nothing compiled) give the verdicts of the
    compiled map and test, with and without the small-step test, across the stable steps, the
    narrow unstable bands above the limit and the steps past it."""
    win = step_limit._windows(undamped)[0]
    ks = np.array([step_limit.contact_stiffness_N_per_m(undamped, f * undamped.delta0_m)
                   for f in (1.0, 1.25**4, 1.25**7, 16.0)])  # fmt: skip
    seen = set()
    for h in np.geomspace(1.0e-6, 12.8e-6, 12):
        for small_step in (False, True):
            want = _compiled_window_verdicts(win, integrator, float(h), ks, small_step)
            got = step_limit._window_stable_many(win, integrator, float(h), ks, small_step)
            assert got == want, (h, small_step)
            seen.update(got)
    assert seen == {True, False}
    coef, idx, kick = stages(win, integrator, 6.5e-6)
    from tests.dem.step_map import position_blocks

    A, B = position_blocks(win.phi, coef, idx, kick, ks, win.left, win.right)
    A2, B2 = step_limit._position_blocks(win, integrator, 6.5e-6, ks)
    assert np.abs(A2 - A).max() <= 1e-13 * np.abs(A).max()
    assert np.abs(B2 - B).max() <= 1e-13 * np.abs(B).max()


def test_block_modes_are_computed_once_per_chain_and_read_only(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Every ``simulate`` call and stability check asks for the block modes (31 eigenproblems,
    about 1.2 ms): a second call on the same chain solves none, and nobody can alter them."""
    chain = dem.build_chain(dem.default_chain_spec())
    calls = {"eigh": 0}
    eigh = simulation.eigh

    def eigh_spy(a: np.ndarray, b: np.ndarray) -> object:
        calls["eigh"] += 1
        return eigh(a, b)

    monkeypatch.setattr(simulation, "eigh", eigh_spy)
    monkeypatch.setattr(simulation, "_MODES", weakref.WeakKeyDictionary())  # as in a new process
    first = simulation.block_modes(chain)
    assert calls["eigh"] == chain.n
    again = simulation.block_modes(chain)
    assert again is first and calls["eigh"] == chain.n
    with pytest.raises(ValueError):
        first.omega[0, 0] = 1.0
    other = dem.build_chain(chain.spec.model_copy(update={"preload": 6.0}))  # its own modes
    simulation.block_modes(other)
    assert calls["eigh"] == 2 * chain.n


def test_a_refusal_on_a_chain_that_ships_nothing_loads_no_compiled_stability_code() -> None:
    """A fresh process refuses an unstable step on a chain that ships no verdicts (the grid scan
    and the search for the largest stable step, which the certificate does not answer) without
    loading or compiling any compiled code: the compiled step map (now ``tests/dem/step_map.py``,
    the tests' reference) compiled for 3 s on a fresh install before the refusal."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    probe = (
        "import sys\n"
        "from sim_backend import dem\n"
        "from sim_backend.dem import step_limit\n"
        "chain = dem.build_chain(dem.load_chain_with_settings(None, ['preload=6 N']))\n"
        "try:\n"
        "    step_limit.check_step(chain, 'blanes-moan4', 50e-6)\n"
        "except step_limit.StepTooLargeError as exc:\n"
        "    print('refused', round(exc.h_max_s * 1e6, 3))\n"
        "import numba\n"
        "compiled = sorted(n for m in list(sys.modules.values())\n"
        "                  if getattr(m, '__name__', '').startswith('sim_backend')\n"
        "                  for n, o in vars(m).items()\n"
        "                  if isinstance(o, numba.core.registry.CPUDispatcher) and o.signatures)\n"
        "print('compiled code loaded', compiled)\n"
    )
    root = Path(__file__).resolve().parents[2]
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_CACHE")}
    out = subprocess.run([sys.executable, "-c", probe], env=env, cwd=root, capture_output=True,
                         text=True, check=True, timeout=300)  # fmt: skip
    assert "refused 6." in out.stdout, out.stdout
    assert "compiled code loaded []" in out.stdout, out.stdout
