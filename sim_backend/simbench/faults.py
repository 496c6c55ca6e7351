"""Fault injection for the simulated bench.

A :class:`FaultPlan` says which faults the simulated instruments show. It is mutable on purpose:
a test (or the bench file, through the bench connection, ``daq.connect``) switches faults on and off
while a run is in progress, and the simulated instruments read it at every command.

Each fault becomes active once ``after_acquisitions`` digitiser records have been read in the
world (0: at once), so a bench file can say "the generator dies after the 5th acquisition".
``generator_silent``, ``digitiser_timeout``, ``digitiser_nan`` and ``vibrometer_signal_lost``
stay active until cleared (:meth:`FaultPlan.clear`), like a broken link. The event faults are
one-shot and switch themselves off once they happened: ``generator_scpi_error`` (queued with the
generator's next command), ``stage_stall`` (the next move stalls) and ``stage_lost_homing`` (the
stage forgets its reference at its next command; homing again recovers).
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

__all__ = ["FAULT_NAMES", "FaultPlan"]


@dataclass
class FaultPlan:
    """Which faults the simulated bench shows.

    Attributes
    ----------
    generator_silent:
        The function generator stops answering: every command times out
        (:class:`instruments.errors.InstrumentTimeout`).
    generator_scpi_error:
        An error string (e.g. ``'-222,"Data out of range"'``) put in the generator's SCPI error
        queue by the next command it receives; ``None``: no error.
    stage_stall:
        The stage stalls on its next move (Zaber warning flag ``FS``, position short of target).
    stage_lost_homing:
        The stage loses its reference (Zaber warning ``WR``): it reports not homed and
        refuses moves.
    digitiser_timeout:
        The digitiser never sees its trigger: ``read()`` times out.
    digitiser_nan:
        The digitiser returns a record full of NaN on the velocity channel.
    vibrometer_signal_lost:
        The vibrometer loses its optical signal: level near 0, no velocity on the analog output.
    after_acquisitions:
        The faults above take effect once this many records have been read (0: at once).
    """

    generator_silent: bool = False
    generator_scpi_error: str | None = None
    stage_stall: bool = False
    stage_lost_homing: bool = False
    digitiser_timeout: bool = False
    digitiser_nan: bool = False
    vibrometer_signal_lost: bool = False
    after_acquisitions: int = 0

    def __post_init__(self) -> None:
        if isinstance(self.after_acquisitions, bool) or not isinstance(
            self.after_acquisitions, int
        ):
            raise ValueError(
                f"faults.after_acquisitions must be an integer, got {self.after_acquisitions!r}"
            )
        if self.after_acquisitions < 0:
            raise ValueError(
                f"faults.after_acquisitions must be >= 0, got {self.after_acquisitions}"
            )
        for f in fields(self):
            if f.name in ("generator_scpi_error", "after_acquisitions"):
                continue
            if not isinstance(getattr(self, f.name), bool):
                raise ValueError(
                    f"faults.{f.name} must be true or false, got {getattr(self, f.name)!r}"
                )
        if self.generator_scpi_error is not None and not isinstance(self.generator_scpi_error, str):
            raise ValueError(
                "faults.generator_scpi_error must be a string such as "
                f"'-222,\"Data out of range\"', got {self.generator_scpi_error!r}"
            )

    @classmethod
    def from_mapping(cls, data: dict[str, Any] | None) -> FaultPlan:
        """Build from a mapping (a bench file's ``faults:`` section); unknown keys are refused."""
        if data is None:
            return cls()
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ValueError(
                f"faults: unknown fault(s) {', '.join(unknown)}; known: {', '.join(sorted(known))}"
            )
        return cls(**data)

    def active(self, n_acquisitions: int) -> bool:
        """Whether the faults are in effect after ``n_acquisitions`` records were read."""
        return n_acquisitions >= self.after_acquisitions

    def any(self) -> bool:
        """Whether any fault is switched on (regardless of ``after_acquisitions``)."""
        return any(getattr(self, name) for name in FAULT_NAMES)

    def clear(self) -> None:
        """Switch every fault off."""
        for name in FAULT_NAMES:
            setattr(self, name, None if name == "generator_scpi_error" else False)
        self.after_acquisitions = 0

    def as_dict(self) -> dict[str, Any]:
        """JSON-serialisable view (for snapshots)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


#: names of the fault switches (everything but ``after_acquisitions``)
FAULT_NAMES: tuple[str, ...] = tuple(
    f.name for f in fields(FaultPlan) if f.name != "after_acquisitions"
)
