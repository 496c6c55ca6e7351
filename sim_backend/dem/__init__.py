"""The discrete-element model (DEM) of the graded cylinder chain.

Cell model from beam theory (:mod:`.beam`), Hertz contacts (:mod:`.contact`), chain files
(:mod:`.spec`), the built chain (:mod:`.chain`), quasi-bands (:mod:`.bands`), the asymmetry-factor
construction (:mod:`.alpha`), drives (:mod:`.drive`) and the compiled integrators
(:mod:`.kernel`, :mod:`.simulation`). SI units throughout.

The names below are imported on first use (PEP 562), so that importing a light submodule
(``sim_backend.dem.kernel_cache``, ``.verdict_store``) does not load scipy and numba.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from sim_backend.dem.alpha import asymmetry_factor, chain_spec_for_alpha
    from sim_backend.dem.bands import Bands, continuum_bands, quasi_bands
    from sim_backend.dem.chain import Chain, build_chain
    from sim_backend.dem.drive import Drive
    from sim_backend.dem.simulation import INTEGRATORS, SimResult, simulate
    from sim_backend.dem.spec import (
        ChainFileError,
        ChainSpec,
        default_chain_spec,
        load_chain_spec,
        load_chain_with_settings,
    )

#: public name -> the submodule that defines it
_WHERE = {
    "asymmetry_factor": "alpha",
    "chain_spec_for_alpha": "alpha",
    "Bands": "bands",
    "continuum_bands": "bands",
    "quasi_bands": "bands",
    "Chain": "chain",
    "build_chain": "chain",
    "Drive": "drive",
    "INTEGRATORS": "simulation",
    "SimResult": "simulation",
    "simulate": "simulation",
    "ChainFileError": "spec",
    "ChainSpec": "spec",
    "default_chain_spec": "spec",
    "load_chain_spec": "spec",
    "load_chain_with_settings": "spec",
}

__all__ = [
    "INTEGRATORS",
    "Bands",
    "Chain",
    "ChainFileError",
    "ChainSpec",
    "Drive",
    "SimResult",
    "asymmetry_factor",
    "build_chain",
    "chain_spec_for_alpha",
    "continuum_bands",
    "default_chain_spec",
    "load_chain_spec",
    "load_chain_with_settings",
    "quasi_bands",
    "simulate",
]


def __getattr__(name: str) -> Any:
    module = _WHERE.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{module}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *_WHERE])
