"""The discrete-element model (DEM) of the graded cylinder chain.

Cell model from beam theory (:mod:`.beam`), Hertz contacts (:mod:`.contact`), chain files
(:mod:`.spec`), the built chain (:mod:`.chain`), quasi-bands (:mod:`.bands`), the asymmetry-factor
construction (:mod:`.alpha`), drives (:mod:`.drive`) and the compiled integrators
(:mod:`.kernel`, :mod:`.simulation`). SI units throughout.
"""

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
