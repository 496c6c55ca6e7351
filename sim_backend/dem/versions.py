"""The model's version: what decides a DEM result besides its inputs.

A result made under one kernel arithmetic (``kernel.NUMERICS_VERSION``) or one mode computation
(``beam.MODES_VERSION``) differs beyond rounding from one made under another, so outputs that
grow over several runs (a design study continued) record it and refuse to mix two."""

from __future__ import annotations


def model_version() -> str:
    """``"kernel <NUMERICS_VERSION>; modes <MODES_VERSION>"`` of this installation."""
    from sim_backend.dem.beam import MODES_VERSION
    from sim_backend.dem.kernel import NUMERICS_VERSION

    return f"kernel {NUMERICS_VERSION}; modes {MODES_VERSION}"
