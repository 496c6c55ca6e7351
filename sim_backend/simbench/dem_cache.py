"""One DEM run per (direction, drive, waveform, window), shared by every cylinder and average.

The world asks :class:`DemRunner` for the chain's response to what the generator played. A run
is keyed by everything that changes the physics (direction, actuator kind, peak drive, the exact
waveform samples and their rate, the window and the output rate), kept in a bounded cache, and
timed, so the benchmark can split DEM seconds from the software around it.

The cache is bounded by its count of runs and by their bytes (:data:`CACHE_BYTES`): a record
holds every cylinder's velocity over the window (31 cylinders x 25 ms at 500 kS/s: 3.2 MB; 1 s
at 1 MS/s: 250 MB), so a count alone let a sweep of long windows hold gigabytes.
"""

from __future__ import annotations

import hashlib
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Literal, cast

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "CACHE_BYTES",
    "CACHE_RUNS",
    "DemKey",
    "DemRecord",
    "DemRunner",
    "DemStats",
    "waveform_digest",
]

#: the most bytes of DEM records the cache keeps (the newest record is kept whatever its size)
CACHE_BYTES = 512 * 2**20
#: the most DEM records the cache keeps
CACHE_RUNS = 1024


@dataclass(frozen=True)
class DemKey:
    """What identifies one DEM run (all SI)."""

    direction: str
    kind: str
    amplitude: float
    waveform_sha1: str
    waveform_rate_Hz: float
    duration_s: float
    sample_rate_Hz: float


@dataclass(frozen=True)
class DemRecord:
    """The chain's response to one drive.

    Attributes
    ----------
    time_s:
        ``[S]`` seconds from the trigger.
    velocity_m_per_s:
        ``[C, S]`` velocity of every cylinder (m/s), cylinder order 1..N.
    drive:
        ``[S]`` the applied drive (m or N).
    meta:
        How it was computed and how good it is: ``integrator``, ``order``, ``dt_s`` (s),
        ``error_estimate_rel`` (step-doubling estimate, relative L2 of the worst cylinder) and
        ``work_not_in_chain_rel`` (the fraction of the input work no longer in the chain at the
        end: dissipated by the damping, plus the integrator's energy error); empty when the
        simulator does not say.
    """

    time_s: NDArray[np.float64]
    velocity_m_per_s: NDArray[np.float64]
    drive: NDArray[np.float64]
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def nbytes(self) -> int:
        """Bytes of the record's arrays."""
        return int(self.time_s.nbytes + self.velocity_m_per_s.nbytes + self.drive.nbytes)


@dataclass
class DemStats:
    """Counters for the benchmark split: DEM calls, cache hits and wall seconds in the DEM."""

    calls: int = 0
    cache_hits: int = 0
    dem_s: float = 0.0

    def as_dict(self) -> dict[str, float | int]:
        return {"dem_calls": self.calls, "dem_cache_hits": self.cache_hits, "dem_s": self.dem_s}


def waveform_digest(samples: NDArray[np.float64]) -> str:
    """SHA-1 of the float64 samples: two waveforms share a DEM run only when identical."""
    return hashlib.sha1(np.ascontiguousarray(samples, dtype=np.float64).tobytes()).hexdigest()


#: computes a record: (key, waveform samples normalised to peak 1) -> DemRecord
Simulator = Callable[[DemKey, NDArray[np.float64]], DemRecord]


class DemRunner:
    """Runs the DEM on demand and caches the records, at most ``cache_size`` of them and
    ``cache_bytes`` bytes of them. The newest record is always kept (even alone above the
    bound: every cylinder and average of one drive use it); beyond the bounds the most recently
    used of the others goes first (:meth:`_evictable`)."""

    def __init__(
        self, simulator: Simulator, cache_size: int = CACHE_RUNS, cache_bytes: int = CACHE_BYTES
    ) -> None:
        self._simulate = simulator
        self._cache: OrderedDict[DemKey, DemRecord] = OrderedDict()
        self._size = cache_size
        self._max_bytes = cache_bytes
        self._bytes = 0
        self.stats = DemStats()
        self._served: dict[DemKey, dict[str, Any]] = {}

    def record(self, key: DemKey, waveform: NDArray[np.float64]) -> DemRecord:
        """The record for ``key`` (``waveform``: the normalised samples the key was made of)."""
        hit = self._cache.get(key)
        if hit is not None:
            self._cache.move_to_end(key)
            self.stats.cache_hits += 1
            self._note_served(key, hit)
            return hit
        t0 = time.perf_counter()
        rec = self._simulate(key, waveform)
        self.stats.dem_s += time.perf_counter() - t0
        self.stats.calls += 1
        self._cache[key] = rec
        self._bytes += rec.nbytes
        while len(self._cache) > 1 and (
            len(self._cache) > self._size or self._bytes > self._max_bytes
        ):
            self._bytes -= self._cache.pop(self._evictable()).nbytes
        self._note_served(key, rec)
        return rec

    def _evictable(self) -> DemKey:
        """The most recently used record but the newest. A sweep whose drives come back in a
        cycle longer than the cache (cylinder the outer loop: every drive once per cylinder)
        then keeps a stable set and hits it; least recently used out first would drop each
        record just before its next use and miss every time."""
        newest_first = reversed(self._cache)
        next(newest_first)
        return next(newest_first)

    def _note_served(self, key: DemKey, rec: DemRecord) -> None:
        if rec.meta and key not in self._served:
            self._served[key] = {
                "direction": key.direction,
                "kind": key.kind,
                "amplitude": key.amplitude,
                "amplitude_units": "m" if key.kind == "displacement" else "N",
                **rec.meta,
            }

    def take_served(self) -> list[dict[str, Any]]:
        """The meta of every distinct run served since the last call (direction, kind,
        amplitude in m or N, integrator, order, dt_s, error_estimate_rel, work_not_in_chain_rel),
        in the order first served; clears the list."""
        out = list(self._served.values())
        self._served.clear()
        return out

    def clear(self) -> None:
        self._cache.clear()
        self._bytes = 0

    @property
    def nbytes(self) -> int:
        """Bytes of the records the cache holds now."""
        return self._bytes

    def __len__(self) -> int:
        return len(self._cache)


def dem_simulator(chain_spec: Any, integrator: str, dt_s: float | None) -> Simulator:
    """A :data:`Simulator` backed by ``sim_backend.dem.simulate`` (imported lazily; the chain is
    built once, on first use)."""
    state: dict[str, Any] = {}

    def simulate_key(key: DemKey, waveform: NDArray[np.float64]) -> DemRecord:
        from sim_backend import dem

        chain = state.get("chain")
        if chain is None:
            spec = chain_spec if chain_spec is not None else dem.default_chain_spec()
            chain = state["chain"] = dem.build_chain(spec)
        drive = dem.Drive(
            direction=cast(Literal["ltr", "rtl"], key.direction),
            kind=cast(Literal["displacement", "force"], key.kind),
            amplitude=key.amplitude,
            burst=None,
            waveform=(np.asarray(waveform, dtype=np.float64), key.waveform_rate_Hz),
        )
        kwargs: dict[str, Any] = {"integrator": integrator, "error_estimate": True}
        if dt_s is not None:
            kwargs["dt_s"] = dt_s
        res = dem.simulate(
            chain,
            [drive],
            duration_s=key.duration_s,
            sample_rate_Hz=key.sample_rate_Hz,
            **kwargs,
        )
        return DemRecord(
            time_s=np.asarray(res.time_s, dtype=np.float64),
            velocity_m_per_s=np.asarray(res.velocity[0], dtype=np.float64),
            drive=np.asarray(res.drive[0], dtype=np.float64),
            meta={
                "integrator": str(res.meta["integrator"]),
                "order": int(res.meta["order"]),
                "dt_s": float(res.meta["dt_s"]),
                "error_estimate_rel": float(res.meta["error_estimate_rel"][0]),
                "work_not_in_chain_rel": float(res.meta["work_not_in_chain_rel"][0]),
            },
        )

    return simulate_key
