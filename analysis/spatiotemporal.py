"""Spatiotemporal view of a scan: velocity envelope against cylinder and time, and where the
packet turns.

At low amplitude the packet entering a graded chain slows down, stops at the cylinder where
its frequency leaves the local band and comes back (the "boomerang" gradon). The map is the
envelope (|analytic signal|, m/s) of every cylinder's velocity; the penetration is the farthest
cylinder, from the entry, whose energy stays within ``threshold_db`` of the most energetic one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from analysis.bands import entry_cylinder
from analysis.envelope import envelope
from analysis.transmission import signal_energy

__all__ = [
    "SpatiotemporalMap",
    "arrival_time_s",
    "energy_beyond_fraction",
    "penetration_cylinder",
    "spatiotemporal_map",
]


@dataclass(frozen=True)
class SpatiotemporalMap:
    """``cylinders [C]`` (1-based), ``time_s [S]``, ``envelope [C, S]`` in m/s (NaN rows for
    unmeasured cylinders)."""

    cylinders: NDArray[np.int32]
    time_s: NDArray[np.float64]
    envelope: NDArray[np.float64]


def spatiotemporal_map(
    velocity: ArrayLike, cylinders: ArrayLike, time_s: ArrayLike
) -> SpatiotemporalMap:
    """Envelope map of ``velocity [C, S]`` (m/s) for ``cylinders [C]`` at ``time_s [S]``."""
    v = np.asarray(velocity, dtype=np.float64)
    if v.ndim != 2:
        raise ValueError(f"velocity must be [C, S], got shape {v.shape}")
    return SpatiotemporalMap(
        np.asarray(cylinders, dtype=np.int32), np.asarray(time_s, dtype=np.float64), envelope(v)
    )


def arrival_time_s(velocity: ArrayLike, time_s: ArrayLike) -> NDArray[np.float64]:
    """Time (s) of the envelope maximum of every record ``[C, S]`` -> ``[C]``.

    NaN where a record is not measured.
    """
    env = envelope(velocity)
    t = np.asarray(time_s, dtype=np.float64)
    k = np.argmax(np.where(np.isfinite(env), env, -1.0), axis=-1)
    out = t[k]
    return np.where(np.all(np.isfinite(env), axis=-1), out, np.nan)


def penetration_cylinder(
    velocity: ArrayLike,
    cylinders: ArrayLike,
    direction: str,
    sample_rate_Hz: float,
    threshold_db: float = -20.0,
) -> int | None:
    """Farthest cylinder (1-based number), from the entry, whose energy is within
    ``threshold_db`` (energy dB, 10 log10) of the most energetic measured cylinder.

    ``velocity [C, S]`` in m/s for ``cylinders [C]``; unmeasured (NaN) cylinders are ignored.
    ``None`` when nothing is measured.
    """
    cyl = np.asarray(cylinders, dtype=np.int64)
    e = signal_energy(velocity, sample_rate_Hz)
    ok = np.isfinite(e)
    if not np.any(ok) or np.nanmax(e) <= 0:
        return None
    n = int(cyl.max())
    entry = entry_cylinder(direction, n)
    strong = ok & (e >= np.nanmax(e) * 10.0 ** (threshold_db / 10.0))
    distance = np.abs(cyl - entry)
    return int(cyl[strong][np.argmax(distance[strong])])


def energy_beyond_fraction(
    velocity: ArrayLike,
    cylinders: ArrayLike,
    direction: str,
    limit_cylinder: int,
    sample_rate_Hz: float,
) -> float:
    """Fraction of the chain's energy (sum over measured cylinders of ``integral v^2 dt``) found
    at or beyond ``limit_cylinder`` (1-based), counted from the entry of ``direction``.

    With the linear limit as ``limit_cylinder`` this is small in the linear regime, where the
    packet turns back before the limit, and grows when the nonlinearity carries energy through.
    ``velocity [C, S]`` in m/s; NaN when nothing is measured.
    """
    cyl = np.asarray(cylinders, dtype=np.int64)
    e = signal_energy(velocity, sample_rate_Hz)
    ok = np.isfinite(e)
    total = float(np.sum(e[ok]))
    if not np.any(ok) or total <= 0:
        return float("nan")
    entry = entry_cylinder(direction, int(cyl.max()))
    beyond = np.abs(cyl - entry) >= abs(limit_cylinder - entry)
    return float(np.sum(e[ok & beyond]) / total)
