"""Quasi-band edges: the default chain's numbers, DEM against continuum, scaling laws."""

from __future__ import annotations

import math
from functools import partial

import numpy as np
import pytest

from sim_backend import dem
from sim_backend.dem import bands
from sim_backend.dem.spec import ChainSpec, MaterialSpec


def test_contact_constants(chain: dem.Chain) -> None:
    assert chain.beta_c == pytest.approx(4.08e9, rel=5e-3)
    assert chain.delta0_m == pytest.approx(1.15e-6, rel=5e-3)
    assert chain.K_lin == pytest.approx(6.5e6, rel=1e-2)
    assert chain.n == 31 and chain.n_modes == 3


def test_default_chain_band_edges(chain: dem.Chain) -> None:
    bands = dem.quasi_bands(chain, 3)
    assert bands.onset_Hz.shape == (31, 3)
    # the central (100 mm) cylinder's first local-resonance band is the paper's two inputs
    assert bands.onset_Hz[15, 1] == pytest.approx(6.62e3, rel=3e-3)
    assert bands.cutoff_Hz[15, 1] == pytest.approx(8.94e3, rel=3e-3)
    assert bands.onset_Hz[0, 1] == pytest.approx(8.08e3, rel=5e-3)
    assert bands.cutoff_Hz[30, 1] == pytest.approx(8.01e3, rel=5e-3)
    # bands slide down along the chain, and are ordered
    assert np.all(np.diff(bands.onset_Hz[:, 1]) < 0)
    assert np.all(np.diff(bands.cutoff_Hz[:, 1]) < 0)
    assert np.all(bands.cutoff_Hz[:, 0] < bands.onset_Hz[:, 1])
    assert np.all(bands.onset_Hz[:, 1] < bands.cutoff_Hz[:, 1])
    # the end cylinders' first local-resonance bands barely overlap
    assert bands.cutoff_Hz[30, 1] < bands.onset_Hz[0, 1]


def test_dem_edges_match_continuum_below_15kHz(chain: dem.Chain) -> None:
    cell = dem.quasi_bands(chain, 3)
    cont = dem.continuum_bands(chain, 3)
    below = cont.cutoff_Hz < 15e3
    assert below.sum() >= 62  # bands 0 and 1 of every cylinder
    np.testing.assert_allclose(cell.cutoff_Hz[below], cont.cutoff_Hz[below], rtol=1e-2)
    on = below.copy()
    on[:, 0] = False
    np.testing.assert_allclose(cell.onset_Hz[on], cont.onset_Hz[on], rtol=1e-2)
    # in fact much better than 1 %
    np.testing.assert_allclose(cell.cutoff_Hz[below], cont.cutoff_Hz[below], rtol=2e-3)


def _edges(**changes: object) -> tuple[float, float]:
    base = dict(
        lengths=("100 mm", "100 mm"), diameter="13.6 mm", preload="5 N",
        beam_theory="euler-bernoulli",
    )  # fmt: skip
    base.update(changes)  # type: ignore[arg-type]
    b = dem.quasi_bands(dem.build_chain(ChainSpec.model_validate(base)), 2)
    return float(b.onset_Hz[0, 1]), float(b.cutoff_Hz[0, 1])


def test_scaling_with_length_and_diameter() -> None:
    on, _ = _edges()
    on_long, _ = _edges(lengths=("200 mm", "200 mm"))
    on_thick, _ = _edges(diameter="20.4 mm")
    assert on_long == pytest.approx(on / 4, rel=1e-9)  # EB: onset ~ d / L^2
    assert on_thick == pytest.approx(on * 1.5, rel=1e-9)


def test_scaling_with_preload() -> None:
    on, cut = _edges()
    on8, cut8 = _edges(preload="40 N")
    assert on8 == pytest.approx(on, rel=1e-12)  # the onset is the free cylinder's
    assert cut8 > cut  # K ~ F0^(1/3) raises the cutoff
    # with K -> 2 K (F0 x 8) the cutoff solves w^2 M(w) = 8 K
    chain8 = dem.build_chain(
        ChainSpec.model_validate(
            dict(lengths=("100 mm", "100 mm"), preload="40 N", beam_theory="euler-bernoulli")
        )
    )
    w = 2 * np.pi * cut8
    m = dem.bands.cell_apparent_mass_kg(chain8, 0, w)
    assert w**2 * m == pytest.approx(4 * chain8.K_lin, rel=1e-9)


def test_scaling_with_material() -> None:
    on, cut = _edges(beam_theory="timoshenko")
    stiff = MaterialSpec(youngs_modulus="288 GPa")
    on4, cut4 = _edges(beam_theory="timoshenko", material=stiff, preload="20 N")
    # E x 4 and F0 x 4 scale every stiffness by 4: all edges x 2
    assert on4 == pytest.approx(2 * on, rel=1e-9)
    assert cut4 == pytest.approx(2 * cut, rel=1e-9)
    heavy = MaterialSpec(density="8800 kg/m^3")
    on_h, cut_h = _edges(beam_theory="timoshenko", material=heavy)
    assert on_h == pytest.approx(on / 2, rel=1e-9)
    assert cut_h == pytest.approx(cut / 2, rel=1e-9)


def test_too_many_bands_refused(chain: dem.Chain) -> None:
    with pytest.raises(ValueError, match="n_bands"):
        dem.quasi_bands(chain, 5)


@pytest.mark.parametrize("degrees", [20.0, 30.0, 45.0, 60.0])
def test_oblique_crossing_matches_the_elliptical_hertz_approximation(degrees: float) -> None:
    """beta_c of cylinders crossed at an angle against Hamrock & Brewe's closed-form fit of the
    elliptical Hertz contact (about 2 % for Ry/Rx >= 3, i.e. up to 60 deg; it degrades towards
    1); 90 deg is exactly the sphere on a flat."""
    from sim_backend.dem.contact import hertz_beta
    from sim_backend.dem.material import FUSED_QUARTZ

    d = 13.6e-3
    R = d / 2
    E_star = FUSED_QUARTZ.contact_modulus_Pa
    assert hertz_beta(d, FUSED_QUARTZ) == pytest.approx(4 / 3 * E_star * math.sqrt(R), rel=1e-12)
    c = abs(math.cos(math.radians(degrees)))
    Rx, Ry = R / (1 + c), R / (1 - c)
    ratio = Ry / Rx
    k = 1.0339 * ratio**0.636
    eps = 1.0003 + 0.5968 / ratio
    fk = 1.5277 + 0.6023 * math.log(ratio)
    r_eff = 1 / (1 / Rx + 1 / Ry)
    delta_1N = fk * (9 / (2 * eps * r_eff) * (1 / (math.pi * k * 2 * E_star)) ** 2) ** (1 / 3)
    beta = hertz_beta(d, FUSED_QUARTZ, math.radians(degrees))
    assert beta == pytest.approx(delta_1N**-1.5, rel=0.02)
    # obliquer crossing: a flatter, stiffer contact; the chain built with it carries it
    assert beta > hertz_beta(d, FUSED_QUARTZ)
    spec = dem.default_chain_spec().model_copy(update={"crossing_angle": math.radians(degrees)})
    assert dem.build_chain(spec).beta_c == pytest.approx(beta)


def _quasi_bands_by_root_search(chain: dem.Chain, n_bands: int) -> bands.Bands:
    """The cell's edges by a root search of its apparent mass (``quasi_bands``' previous method,
    the continuum check's ``_edges`` on the DEM cell), the reference of the eigenvalue edges."""
    onset = np.empty((chain.n, n_bands))
    cutoff = np.empty((chain.n, n_bands))
    for i in range(chain.n):
        onset[i], cutoff[i] = bands._edges(
            partial(bands.cell_apparent_mass_kg, chain, i),
            chain.omega_res_rad_s[i],
            4.0 * chain.K_lin,
            n_bands,
        )
    return bands.Bands(onset, cutoff)


@pytest.mark.parametrize(
    "update", [{}, {"n_modes": 6}, {"preload": 0.5}, {"n_cylinders": 5, "n_modes": 1}]
)
def test_cell_edges_by_eigenvalues_equal_the_root_search(update: dict[str, object]) -> None:
    """The cell's edges as eigenfrequencies of its block (free, and held by 4K) are the roots of
    its apparent mass that the previous root search found, for every band count."""
    chain = dem.build_chain(dem.default_chain_spec().model_copy(update=update))
    for n_bands in range(1, chain.n_modes + 2):
        got = dem.quasi_bands(chain, n_bands)
        ref = _quasi_bands_by_root_search(chain, n_bands)
        scale = ref.cutoff_Hz.max()
        assert np.abs(got.onset_Hz - ref.onset_Hz).max() <= 1e-12 * scale
        assert np.abs(got.cutoff_Hz - ref.cutoff_Hz).max() <= 1e-12 * scale


def test_run_protocol_on_the_simulated_bench_imports_no_scipy_optimize(tmp_path: object) -> None:
    """The bench's chain information (its quasi-bands) needs no root search: scipy.optimize
    (0.3 s to import) is not loaded by a smoke run."""
    import subprocess
    import sys
    from pathlib import Path

    out = Path(str(tmp_path)) / "smoke.h5"
    probe = (
        "import sys\n"
        "from daq.cli.run_protocol import main\n"
        f"sys.argv = ['run_protocol', 'smoke', '--out', {str(out)!r}, '--quiet']\n"
        "code = main()\n"
        "print('exit', code, 'scipy.optimize' in sys.modules)\n"
    )
    root = Path(__file__).resolve().parents[2]
    res = subprocess.run([sys.executable, "-c", probe], cwd=root, capture_output=True,
                         text=True, timeout=600)  # fmt: skip
    assert "exit 0 False" in res.stdout, res.stdout + res.stderr
