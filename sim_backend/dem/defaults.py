"""The model's default integrator and steps, in a module that imports nothing heavy (no numpy,
no numba), so that a run's estimate (:mod:`daq.engine.eta`) reads them before the kernel is
loaded; :mod:`sim_backend.dem.simulation` uses and re-exports them."""

from __future__ import annotations

__all__ = ["DEFAULT_DT_S", "DEFAULT_DT_TOP_HZ", "DEFAULT_INTEGRATOR"]

DEFAULT_INTEGRATOR = "blanes-moan4"
#: default step (s) of each integrator (chosen from benchmarks/dem_sweep: error <= 1e-4)
DEFAULT_DT_S: dict[str, float] = {
    "strang": 0.1e-6,
    "yoshida4": 1.0e-6,
    "suzuki4": 1.0e-6,
    "blanes-moan4": 2.0e-6,
    "yoshida6": 2.0e-6,
}
#: the default steps hold for block modes up to this frequency (the default chain's top block
#: mode is 82 kHz); stiffer blocks (more modes, shorter cylinders) get proportionally smaller steps
DEFAULT_DT_TOP_HZ = 85.0e3
