"""The integrators of the DEM by name: symmetric splittings of drift (the modes' exact linear
flow) and kick (the contact forces), their order and weights, and the one-line refusal of a name
that is none of them. No numba here: a bench or study file's integrator is checked without
loading the kernel."""

from __future__ import annotations

from collections.abc import Sequence

__all__ = ["INTEGRATORS", "integrator_error"]

_W1 = 1.0 / (2.0 - 2.0 ** (1.0 / 3.0))
_W0 = 1.0 - 2.0 * _W1
_Z1 = 1.0 / (2.0 - 2.0 ** (1.0 / 5.0))
_Z0 = 1.0 - 2.0 * _Z1
_P = 1.0 / (4.0 - 4.0 ** (1.0 / 3.0))


def _from_strang(gamma: Sequence[float]) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """(drift weights a [m+1], kick weights b [m]) of a composition of Strang steps gamma."""
    m = len(gamma)
    a = [0.5 * gamma[0]]
    a += [0.5 * (gamma[k - 1] + gamma[k]) for k in range(1, m)]
    a += [0.5 * gamma[-1]]
    return tuple(a), tuple(gamma)


# Blanes & Moan, J. Comput. Appl. Math. 142 (2002) 313, Table 2: S6, order 4, 6 kicks
_BM_A = (0.0792036964311957, 0.353172906049774, -0.0420650803577195)
_BM_B = (0.209515106613362, -0.143851773179818)
_BM4 = (
    (*_BM_A, 1.0 - 2.0 * sum(_BM_A), *_BM_A[::-1]),
    (*_BM_B, 0.5 - sum(_BM_B), 0.5 - sum(_BM_B), *_BM_B[::-1]),
)

#: symmetric splittings D(a0 h) K(b0 h) D(a1 h) ... K(b_{m-1} h) D(a_m h):
#: name -> (order, drift weights a, kick weights b)
INTEGRATORS: dict[str, tuple[int, tuple[float, ...], tuple[float, ...]]] = {
    "strang": (2, *_from_strang((1.0,))),
    "yoshida4": (4, *_from_strang((_W1, _W0, _W1))),
    "suzuki4": (4, *_from_strang((_P, _P, 1.0 - 4.0 * _P, _P, _P))),
    "blanes-moan4": (4, *_BM4),
    "yoshida6": (6, *_from_strang(tuple(z * w for z in (_Z1, _Z0, _Z1) for w in (_W1, _W0, _W1)))),
}


def integrator_error(name: object) -> str | None:
    """Why ``name`` is not an integrator (``"default"`` or a key of :data:`INTEGRATORS`), in
    one line; ``None`` when it is one."""
    if name == "default" or (isinstance(name, str) and name in INTEGRATORS):
        return None
    return f"unknown integrator {name!r}; choose from default, {', '.join(sorted(INTEGRATORS))}"
