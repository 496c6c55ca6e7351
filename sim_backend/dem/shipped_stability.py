"""Step-stability verdicts shipped with the package, for the shipped chains at the shipped steps.

:func:`sim_backend.dem.step_limit.stable_up_to` decides once per (chain, integrator, step) whether
a step is stable up to a contact overlap, and keeps the verdict in the user's cache folder. For
the chains that ship (:func:`~sim_backend.dem.spec.default_chain_spec`,
:func:`~sim_backend.dem.spec.benchmark_chain_spec`) at the steps that the shipped protocols make
the simulated bench check, the verdict is computed at release time instead and shipped as package
data (``chains/step_stability.json``), so that even the first run of a fresh install computes
nothing: :func:`lookup` is asked after the memory and the user's cache and before computing.

Which steps: the simulated bench runs the DEM at the protocol's sample rate (``protocols/*.yaml``:
200 and 500 kS/s; 500 kS/s is also ``simulate``'s default rate) with the default integrator and
its default step ``h`` and a step-doubling error estimate, whose rerun at ``2h`` is the step
``simulate`` checks (:func:`checked_step`). Each verdict is scanned up to the overlap of a
:data:`MAX_DISPLACEMENT_M` displacement drive (twice the simulated bench's largest drive: 10 Vpp
from the generator, gain 20, 0.05 um/V) and, like the user's cache, keyed by the chain's content,
the integrator, the step and ``MODES_VERSION``: a change of the chain, the modes or the scan makes
its keys miss (nothing wrong is served) and ``tests/dem/test_shipped_stability.py``, which
recomputes every verdict, fail until the table is regenerated::

    python -m sim_backend.dem.shipped_stability     # rewrites chains/step_stability.json
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

__all__ = [
    "MAX_DISPLACEMENT_M",
    "SHIPPED_FILE",
    "SHIPPED_RATES_HZ",
    "checked_step",
    "compute_table",
    "lookup",
    "shipped_configurations",
]

#: the table (package data next to the shipped chain files)
SHIPPED_FILE = Path(__file__).with_name("chains") / "step_stability.json"
#: the shipped protocols' sample rates (protocols/*.yaml; 500 kS/s is simulate's default too)
SHIPPED_RATES_HZ = (200.0e3, 500.0e3)
#: each verdict is scanned up to the reference overlap of a displacement drive of this size (m)
MAX_DISPLACEMENT_M = 10.0e-6

_TABLE: dict[str, tuple[float, float, float]] | None = None


def _scan_settings() -> dict[str, Any]:
    from sim_backend.dem.beam import MODES_VERSION
    from sim_backend.dem.step_limit import RANGE_RATIO, STABILITY_TOL

    return {"modes_version": MODES_VERSION, "range_ratio": RANGE_RATIO, "tol": STABILITY_TOL}


def _load() -> dict[str, tuple[float, float, float]]:
    """The shipped verdicts by key (empty when the file is missing, unreadable or was made with
    other scan settings)."""
    global _TABLE
    if _TABLE is None:
        table: dict[str, tuple[float, float, float]] = {}
        try:
            data = json.loads(SHIPPED_FILE.read_text())
            if data.get("settings") == _scan_settings():
                for key, e in data["verdicts"].items():
                    table[key] = (float(e["start_m"]), float(e["stable_to_m"]),
                                  float(e["unstable_at_m"]))  # fmt: skip
        except (OSError, ValueError, TypeError, KeyError, AttributeError):
            table = {}
        _TABLE = table
    return _TABLE


def lookup(key: str) -> tuple[float, float, float] | None:
    """The shipped verdict ``(start_m, stable_to_m, unstable_at_m)`` (m; inf: no unstable
    overlap found) of a :func:`sim_backend.dem.step_limit` range key, or ``None``."""
    return _load().get(key)


def checked_step(chain: Any, rate_Hz: float, integrator: str = "default") -> float:
    """The step (s) that ``simulate(chain, ..., sample_rate_Hz=rate_Hz, error_estimate=True)``
    checks with the integrator's default step: ``2h``, the step of the error estimate's rerun
    at ``rate_Hz / 2`` (by simulate's own step functions)."""
    from sim_backend.dem.simulation import DEFAULT_INTEGRATOR, default_step_s, steps_per_sample

    name = DEFAULT_INTEGRATOR if integrator == "default" else integrator
    _, h = steps_per_sample(default_step_s(chain, name), rate_Hz)
    return steps_per_sample(2.0 * h, rate_Hz / 2.0)[1]


def shipped_configurations() -> list[tuple[str, Any, str, float, float]]:
    """``(chain name, chain, integrator, step s, rate Hz)`` of every shipped verdict."""
    from sim_backend.dem.chain import build_chain
    from sim_backend.dem.simulation import DEFAULT_INTEGRATOR
    from sim_backend.dem.spec import benchmark_chain_spec, default_chain_spec

    out = []
    for name, spec in (("default", default_chain_spec()), ("benchmark", benchmark_chain_spec())):
        chain = build_chain(spec)
        for rate in SHIPPED_RATES_HZ:
            out.append((name, chain, DEFAULT_INTEGRATOR, checked_step(chain, rate), rate))
    return out


def compute_table() -> dict[str, Any]:
    """Compute every shipped verdict afresh (no cache read or written): the file's content."""
    from instruments.burst import Burst
    from sim_backend.dem.drive import Drive
    from sim_backend.dem.step_limit import range_key, reference_overlap_m, scan_range

    verdicts: dict[str, Any] = {}
    for name, chain, integrator, h, rate in shipped_configurations():
        drive = Drive("ltr", "displacement", MAX_DISPLACEMENT_M, burst=Burst(8.92e3))
        upto = reference_overlap_m(chain, [drive])
        v = scan_range(chain, integrator, h, upto)
        verdicts[range_key(chain, integrator, h)] = {
            "chain": name,
            "integrator": integrator,
            "step_s": h,
            "rate_Hz": rate,
            "scanned_to_m": upto,
            "start_m": v.start_m,
            "stable_to_m": v.stable_to_m,
            "unstable_at_m": v.unstable_at_m if math.isfinite(v.unstable_at_m) else "inf",
        }
    return {
        "about": "step-stability verdicts of the shipped chains at the shipped protocols' steps; "
        "written by `python -m sim_backend.dem.shipped_stability`, checked by "
        "tests/dem/test_shipped_stability.py",
        "settings": _scan_settings(),
        "verdicts": verdicts,
    }


def main() -> int:
    """Rewrite :data:`SHIPPED_FILE`."""
    global _TABLE
    table = compute_table()
    SHIPPED_FILE.write_text(json.dumps(table, indent=1) + "\n")
    _TABLE = None
    print(f"{SHIPPED_FILE}: {len(table['verdicts'])} verdicts")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
