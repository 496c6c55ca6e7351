"""Re-open a run file whose writer was killed (the functions live in :mod:`protocols.recover`,
next to the run-file layout, so readers below ``daq`` can use them)."""

from protocols.recover import ClearedView, clear_consistency_flags, has_consistency_flags, lookup3

__all__ = ["ClearedView", "clear_consistency_flags", "has_consistency_flags", "lookup3"]
