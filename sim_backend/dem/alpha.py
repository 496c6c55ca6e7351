"""The paper's asymmetry factor and the chain built for a given one.

alpha = (alpha_c + alpha_s) / 2 with alpha_c = |f_c,1 - f_c,N| / f_c,cen (cutoff of the first
local-resonance band) and alpha_s = |f_s,1 - f_s,N| / f_s,cen (its onset). The construction keeps
the central cylinder (its length, hence its edges) fixed and tilts the onset edge linearly along
the chain, ``f_s,i = f_s,cen (1 - t x_i)`` with ``x_i`` from -1/2 (#1) to +1/2 (#N); each length
is solved from its onset, and ``t`` is solved so that the chain's alpha is the one asked for.
"""

from __future__ import annotations

import math
from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from sim_backend.dem.bands import Bands
from sim_backend.dem.beam import beam_modes
from sim_backend.dem.contact import hertz_beta, linear_stiffness
from sim_backend.dem.spec import ChainFileError, ChainSpec, default_chain_spec

if TYPE_CHECKING:  # scipy.interpolate costs 0.3-1 s to import: only where a chain is designed
    from scipy.interpolate import CubicSpline

__all__ = ["asymmetry_factor", "chain_spec_for_alpha"]

#: lengths are searched within this factor of the central length
_LENGTH_RANGE = (0.4, 2.5)


def asymmetry_factor(bands: Bands) -> float:
    """alpha of a chain from its bands (band 1 = first local-resonance band)."""
    fs = bands.onset_Hz[:, 1]
    fc = bands.cutoff_Hz[:, 1]
    n = fs.size
    if n % 2 == 1:
        fs_cen, fc_cen = fs[n // 2], fc[n // 2]
    else:
        fs_cen = 0.5 * (fs[n // 2 - 1] + fs[n // 2])
        fc_cen = 0.5 * (fc[n // 2 - 1] + fc[n // 2])
    return 0.5 * (abs(fc[0] - fc[-1]) / fc_cen + abs(fs[0] - fs[-1]) / fs_cen)


def _band1_edges(length_m: float, spec: ChainSpec) -> tuple[float, float]:
    """(onset, cutoff) of the first local-resonance band of one cylinder, Hz."""
    from scipy.optimize import brentq

    material = spec.material.to_material()
    modes = beam_modes(length_m, spec.diameter, material, spec.n_modes, spec.beam_theory)
    k4 = 4.0 * linear_stiffness(spec.preload, hertz_beta(spec.diameter, material))
    w = modes.omega_rad_s
    mj = modes.modal_mass_kg

    def mass(x: float) -> float:
        return float(modes.residual_mass_kg + np.sum(mj * w**2 / (w**2 - x * x)))

    hi = float(w[1]) if w.size > 1 else float(w[0]) * 10.0
    lo = float(w[0]) * (1 + 1e-9)
    hi_in = hi * (1 - 1e-9)
    onset = brentq(mass, lo, hi_in, xtol=1e-10, rtol=1e-13)
    if w.size == 1:
        z = hi_in
        while z * z * mass(z) < k4:
            z *= 2.0
        hi_in = z
    cutoff = brentq(lambda x: x * x * mass(x) - k4, lo, hi_in, xtol=1e-10, rtol=1e-13)
    return onset / (2 * math.pi), cutoff / (2 * math.pi)


@lru_cache(maxsize=16)
def _edge_splines(spec_json: str, l_cen: float) -> tuple[CubicSpline, CubicSpline, CubicSpline]:
    """Splines in log space: length from onset, onset from length, cutoff from length."""
    from scipy.interpolate import CubicSpline

    spec = ChainSpec.model_validate_json(spec_json)
    lengths = l_cen * np.geomspace(_LENGTH_RANGE[0], _LENGTH_RANGE[1], 161)
    edges = np.array([_band1_edges(float(L), spec) for L in lengths])
    log_l = np.log(lengths)
    # onset falls with length: ascending onset for the inverse
    inv = CubicSpline(np.log(edges[::-1, 0]), log_l[::-1])
    return inv, CubicSpline(log_l, np.log(edges[:, 0])), CubicSpline(log_l, np.log(edges[:, 1]))


def _lengths_for_tilt(
    t: float, spec: ChainSpec, l_cen: float, x: NDArray[np.float64]
) -> NDArray[np.float64]:
    inv, onset, _ = _edge_splines(spec.model_dump_json(), l_cen)
    fs_cen = float(np.exp(onset(math.log(l_cen))))
    target = fs_cen * (1.0 - t * x)
    lo = math.exp(float(onset(math.log(l_cen * _LENGTH_RANGE[1]))))
    hi = math.exp(float(onset(math.log(l_cen * _LENGTH_RANGE[0]))))
    if target.min() <= lo or target.max() >= hi:
        raise ValueError("out of range")
    return np.asarray(np.exp(inv(np.log(target))), dtype=np.float64)


def chain_spec_for_alpha(alpha: float, base: ChainSpec | None = None) -> ChainSpec:
    """The chain with asymmetry factor ``alpha`` around ``base``'s central cylinder.

    ``base`` (default: the default chain) gives N, the central length (mean of the two middle
    lengths for even N), diameter, preload, material, modes, ends and damping. Raises
    :class:`ChainFileError` naming ``alpha`` when no such chain exists.
    """
    from scipy.optimize import brentq

    base = base if base is not None else default_chain_spec()
    if not (isinstance(alpha, int | float) and math.isfinite(alpha) and alpha >= 0.0):
        raise ChainFileError(f"alpha: must be a finite number >= 0, got {alpha!r}")
    lengths0 = base.lengths_m()
    n = lengths0.size
    l_cen = float(
        lengths0[n // 2] if n % 2 == 1 else 0.5 * (lengths0[n // 2 - 1] + lengths0[n // 2])
    )
    x = (np.arange(n) - 0.5 * (n - 1)) / (n - 1)
    if alpha == 0.0:
        return base.model_copy(
            update={"lengths": tuple([l_cen] * n), "n_cylinders": None,
                    "length_first": None, "length_last": None}
        )  # fmt: skip

    _, onset, cutoff = _edge_splines(base.model_dump_json(), l_cen)

    def alpha_of(t: float) -> float:
        ends = np.log(_lengths_for_tilt(t, base, l_cen, x)[[0, -1]])
        fs, fc = np.exp(onset(ends)), np.exp(cutoff(ends))
        fs_cen, fc_cen = (
            math.exp(float(onset(math.log(l_cen)))),
            math.exp(float(cutoff(math.log(l_cen)))),
        )
        return float(0.5 * (abs(fc[0] - fc[1]) / fc_cen + abs(fs[0] - fs[1]) / fs_cen))

    # largest tilt that stays inside the length range
    t_hi = 1.999
    while True:
        try:
            _lengths_for_tilt(t_hi, base, l_cen, x)
            break
        except ValueError:
            t_hi *= 0.9
            if t_hi < 1e-6:
                raise ChainFileError("alpha: no chain found") from None
    if alpha_of(t_hi) < alpha:
        raise ChainFileError(
            f"alpha: {alpha:g} is impossible for this chain "
            f"(largest reachable about {alpha_of(t_hi):.3g})"
        )
    t = brentq(lambda s: alpha_of(s) - alpha, 0.0, t_hi, xtol=1e-12, rtol=1e-10)
    lengths = _lengths_for_tilt(t, base, l_cen, x)
    if n % 2 == 1:
        lengths[n // 2] = l_cen
    spec = base.model_copy(
        update={"lengths": tuple(float(v) for v in lengths), "n_cylinders": None,
                "length_first": None, "length_last": None}
    )  # fmt: skip
    return spec
