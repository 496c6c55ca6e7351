"""What ``biafc simulate`` refuses before the model runs: the protocol's bounds on the record
and the burst (:func:`protocols.schema.outside_bounds`), the burst within the run and below the
record's Nyquist frequency, and the memory the run would hold.

Before, only "> 0" was checked: ``--duration 100s`` at 500 kS/s grew to 24 GB and the host's
out-of-memory killer ended it (and shook every other process on the machine); ``--frequency
1MHz`` at 500 kS/s, 100 000 cycles or a burst wider than its centre frequency ran and wrote a
file of aliased data. Each refusal is one line naming the option, the value and the range. A
run shorter than its burst is allowed (the model runs the burst's start: a short window is
the quick look the tests and a physicist take), unlike a protocol's record or a study's window.

The checks themselves are :func:`protocols.model_request.model_request_error`, which a study
file's check (:mod:`protocols.study`) shares; this module names the command's options.
"""

from __future__ import annotations

from typing import Any

from protocols.model_request import (
    MAX_SIMULATE_BYTES,
    RequestNames,
    model_request_error,
    within,
)

__all__ = ["MAX_SIMULATE_BYTES", "simulate_request_error", "within"]


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
    names = RequestNames(frequency=frequency_option, burst=burst_option, records=records_option)
    why = model_request_error(duration_s, rate_Hz, burst, n_records, names)
    return None if why is None else f"{why[0]}: {why[1]}"
