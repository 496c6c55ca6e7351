"""Fixtures shared by the DEM tests: the paper's default chain, damped and undamped."""

from __future__ import annotations

import pytest

from sim_backend import dem
from sim_backend.dem.spec import DampingSpec


@pytest.fixture(scope="session")
def chain() -> dem.Chain:
    """The default chain (31 cylinders, J = 3, default damping)."""
    return dem.build_chain(dem.default_chain_spec())


@pytest.fixture(scope="session")
def undamped() -> dem.Chain:
    """The default chain with every damping ratio 0 (energy balances exactly)."""
    spec = dem.default_chain_spec().model_copy(
        update={"damping": DampingSpec(bending_mode_ratio=0.0, contact_dashpot_ratio=0.0)}
    )
    return dem.build_chain(spec)


@pytest.fixture(scope="session")
def dashpot_chain() -> dem.Chain:
    """The default chain with the contact dashpot on (0.005): the benchmarks' scene."""
    from sim_backend.dem.spec import benchmark_chain_spec

    return dem.build_chain(benchmark_chain_spec())
