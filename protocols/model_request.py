"""What a model run refuses before it runs: the record and the burst within the protocol's
bounds (:func:`protocols.schema.outside_bounds`), the burst below the record's Nyquist
frequency, and the memory the run would hold; for a run whose numbers are read off the whole
burst (a design study), the window holding the burst.

One source of truth for ``biafc simulate``, ``accuracy`` and ``regime``
(``daq/cli/simulate_request.py`` names their options) and for a study file
(:mod:`protocols.study`, naming its fields): each refusal is ``(field, why)``, the field that
set what is refused (an option or a study file's dotted field) and one line naming the value
and the range.

Before, a study checked only "> 0": a 10 kS/s record of the 8.92/6.63 kHz carriers (above
its Nyquist frequency), a 150 kHz carrier at 200 kS/s or a 0.5 ms window against a 3 ms burst
ran, and every cell was stored "ok" with numbers of aliased or cut-off signals.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from instruments.units import format_quantity
from protocols.schema import outside_bounds

__all__ = ["MAX_SIMULATE_BYTES", "RequestNames", "model_request_error", "within"]

#: the largest output of ``biafc simulate`` or a ``biafc regime`` batch (the velocity of every
#: cylinder and the drive, float64): a run holds 3-4 times its output while it runs (resident:
#: 1.1 GB for simulate's 256 MB, 2 s at 500 kS/s; 1.7 GB for regime's 492 MB, 128 amplitudes),
#: so this bound keeps a run near 4 GB, and regime's largest --count (256) within it
MAX_SIMULATE_BYTES = 2**30


@dataclass(frozen=True)
class RequestNames:
    """Who set each number, as the refusal names it: ``duration``, ``rate``; ``frequency``
    (None: the caller has no such setting, and a burst above the Nyquist frequency is said of
    ``rate``); ``burst`` (what set the burst's length: ``--cycles``, ``--width``, a study's
    ``drive.burst``); ``cycles`` (what set a burst's cycles); ``records`` (what set the number
    of records, named with ``duration`` when the output is too large)."""

    duration: str = "--duration"
    rate: str = "--rate"
    frequency: str | None = "--frequency"
    burst: str = "--frequency"
    cycles: str = "--cycles"
    records: str | None = None


def within(option: str, value: float, bound: str, dimension: str) -> str | None:
    """Why ``value`` (SI) of ``option`` is outside the protocol's bounds ``[bound]``
    (:func:`protocols.schema.outside_bounds`), or None."""
    why = outside_bounds(bound, value, dimension)
    return None if why is None else f"{option}: {why}"


def _split(why: str | None) -> tuple[str, str] | None:
    if why is None:
        return None
    field, _, rest = why.partition(": ")
    return field, rest


def model_request_error(
    duration_s: float,
    rate_Hz: float,
    burst: Any,
    n_records: int | None,
    names: RequestNames = RequestNames(),
    *,
    whole_burst: bool = False,
) -> tuple[str, str] | None:
    """Why a run of ``duration_s`` (s) at ``rate_Hz`` (S/s) with ``burst``
    (``instruments.burst.Burst``) recording ``n_records`` traces (None: not bounded here)
    cannot be run: ``(field, why)`` with the field named by ``names``, or None.
    ``whole_burst``: the window must hold the whole burst (a study's metrics integrate it)."""
    for err in (
        within(names.duration, duration_s, "duration", "time"),
        within(names.rate, rate_Hz, "rate", "sample_rate"),
        within(names.frequency or "the burst", burst.f_center_Hz, "f_center", "frequency"),
    ):
        if err is not None:
            return _split(err)
    if burst.cycles is not None:
        err = within(names.cycles, float(burst.cycles), "cycles", "")
        if err is not None:
            return _split(err)
    f_c = format_quantity(burst.f_center_Hz, "frequency")
    if not burst.sigma_f_Hz < burst.f_center_Hz:
        return names.burst, (
            f"the burst's spectral width {format_quantity(burst.sigma_f_Hz, 'frequency')} is "
            f"not below its centre frequency {f_c}; give a longer burst"
        )
    f_top = burst.f_center_Hz + 3.0 * burst.sigma_f_Hz
    if f_top >= rate_Hz / 2:
        lower = f" or lower {names.frequency}" if names.frequency else ""
        return names.frequency or names.rate, (
            f"the {f_c} burst (up to {format_quantity(f_top, 'frequency')} with its band) is "
            f"above the Nyquist frequency {format_quantity(rate_Hz / 2, 'frequency')} of "
            f"{names.rate} {format_quantity(rate_Hz, 'sample_rate')}; record at more than "
            f"{format_quantity(2 * f_top, 'sample_rate')}{lower}"
        )
    if whole_burst and burst.duration_s > duration_s * (1 + 1e-9):
        cycles = f", {burst.cycles:g} cycles" if burst.cycles is not None else ""
        return names.duration, (
            f"{format_quantity(duration_s, 'time')} is shorter than the {f_c} burst "
            f"({format_quantity(burst.duration_s, 'time')}{cycles}); give at "
            f"least {format_quantity(burst.duration_s, 'time')} (up to 10 s) or a shorter "
            f"burst ({names.burst})"
        )
    if n_records is None:
        return None
    samples = math.floor(duration_s * rate_Hz) + 1
    data = samples * n_records * 8
    if data > MAX_SIMULATE_BYTES:
        lead = names.records or names.duration
        fewer = f"lower {names.records.split()[0]}, " if names.records else ""
        return lead, (
            f"the run's output would be {data / 2**20:,.0f} MiB ({samples:,} "
            f"samples x {n_records} records x 8 bytes, more than that in memory while it "
            f"runs), above the bound of {MAX_SIMULATE_BYTES / 2**30:g} GiB; {fewer}shorten "
            f"{names.duration} or lower {names.rate}"
        )
    return None
