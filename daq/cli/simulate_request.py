"""What ``biafc simulate`` refuses before the model runs: the protocol's bounds on the record
and the burst (:func:`protocols.schema.outside_bounds`), the burst within the run and below the
record's Nyquist frequency, and the memory the run would hold.

Before, only "> 0" was checked: ``--duration 100s`` at 500 kS/s grew to 24 GB and the host's
out-of-memory killer ended it (and shook every other process on the machine); ``--frequency
1MHz`` at 500 kS/s, 100 000 cycles or a burst wider than its centre frequency ran and wrote a
file of aliased data. Each refusal is one line naming the option, the value and the range. A
run shorter than its burst is allowed (the model runs the burst's start: a short window is
the quick look the tests and a physicist take), unlike a protocol's record.
"""

from __future__ import annotations

import math
from typing import Any

from instruments.units import format_quantity
from protocols.schema import outside_bounds

#: the largest output of ``biafc simulate`` or a ``biafc regime`` batch (the velocity of every
#: cylinder and the drive, float64): a run holds 3-4 times its output while it runs (resident:
#: 1.1 GB for simulate's 256 MB, 2 s at 500 kS/s; 1.7 GB for regime's 492 MB, 128 amplitudes),
#: so this bound keeps a run near 4 GB, and regime's largest --count (256) within it
MAX_SIMULATE_BYTES = 2**30


def within(option: str, value: float, bound: str, dimension: str) -> str | None:
    """Why ``value`` (SI) of ``option`` is outside the protocol's bounds ``[bound]``
    (:func:`protocols.schema.outside_bounds`), or None."""
    why = outside_bounds(bound, value, dimension)
    return None if why is None else f"{option}: {why}"


def simulate_request_error(
    duration_s: float,
    rate_Hz: float,
    burst: Any,
    n_records: int,
    *,
    burst_option: str = "--frequency",
    records_option: str | None = None,
    frequency_option: str | None = "--frequency",
) -> str | None:
    """Why a run of ``duration_s`` (s) at ``rate_Hz`` (S/s) with ``burst``
    (``instruments.burst.Burst``) recording ``n_records`` traces (every cylinder and the drive,
    of every trajectory of a batch) cannot be simulated, or None.
    ``burst_option``: the option that set the burst's length (``--cycles``, ``--width``,
    ``--sigma-f``, ``--burst``), named when the burst does not fit the run;
    ``records_option``: the option that set ``n_records`` (``--count`` of a batch), named with
    ``--duration`` when the output is too large; ``frequency_option``: the option that set
    the burst's frequency (None: the command has none, and a burst above the Nyquist frequency
    is said of ``--rate``)."""
    for why in (
        within("--duration", duration_s, "duration", "time"),
        within("--rate", rate_Hz, "rate", "sample_rate"),
        within(frequency_option or "the burst", burst.f_center_Hz, "f_center", "frequency"),
    ):
        if why is not None:
            return why
    if burst.cycles is not None:
        why = within("--cycles", float(burst.cycles), "cycles", "")
        if why is not None:
            return why
    if not burst.sigma_f_Hz < burst.f_center_Hz:
        return (
            f"{burst_option}: the burst's spectral width "
            f"{format_quantity(burst.sigma_f_Hz, 'frequency')} is not below its centre "
            f"frequency {format_quantity(burst.f_center_Hz, 'frequency')}; give a longer burst"
        )
    f_top = burst.f_center_Hz + 3.0 * burst.sigma_f_Hz
    if f_top >= rate_Hz / 2:
        lower = f" or lower {frequency_option}" if frequency_option else ""
        return (
            f"{frequency_option or '--rate'}: the {format_quantity(burst.f_center_Hz, 'frequency')}"
            f" burst (up to {format_quantity(f_top, 'frequency')} with its band) is above the "
            f"Nyquist frequency {format_quantity(rate_Hz / 2, 'frequency')} of --rate "
            f"{format_quantity(rate_Hz, 'sample_rate')}; record at more than "
            f"{format_quantity(2 * f_top, 'sample_rate')}{lower}"
        )
    samples = math.floor(duration_s * rate_Hz) + 1
    data = samples * n_records * 8
    if data > MAX_SIMULATE_BYTES:
        lead = records_option or "--duration"
        fewer = f"lower {records_option.split()[0]}, " if records_option else ""
        return (
            f"{lead}: the run's output would be {data / 2**20:,.0f} MiB ({samples:,} "
            f"samples x {n_records} records x 8 bytes, more than that in memory while it "
            f"runs), above the bound of {MAX_SIMULATE_BYTES / 2**30:g} GiB; {fewer}shorten "
            "--duration or lower --rate"
        )
    return None
