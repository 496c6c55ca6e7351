"""Parsed units remembered across processes, so that pint is imported only for a unit this
machine has not read before.

Importing pint and building the project's registry took 0.15-0.23 s of every command that reads
a bench file or a protocol (a tenth of a warm ``run_protocol smoke.yaml``), to answer the same
few questions each time: what is ``"nm"`` as a length, ``"kHz"`` as a frequency.
:func:`instruments.units.parse_quantity` asks :class:`UnitMemo` first and pint only on a miss;
pint's answer (the factor to the dimension's unit, or why there is none) is then kept. pint
stays the one place the units are defined: the memo holds nothing pint has not said.

One JSON file in the user cache folder (:func:`instruments.user_cache.cache_dir`),
``units-<key>.json``, ``{"<unit>\\u0000<dimension>": [factor or null, what]}``, read and merged
as the stability verdicts' file is (:mod:`instruments.cache_entries`: a damaged file is an empty
memo, a file is replaced whole, a cache folder that cannot be written only costs the speed-up).
The key hashes what an answer depends on, given by the caller: the units module's own source
(its definitions, dimensions and reading rules) and the installed pint (its file's path, size
and time), so an edit or an upgrade starts a new file. Floats are kept as JSON writes them
(``repr``: exact).
"""

from __future__ import annotations

import hashlib
import math
import threading
from collections.abc import Iterable
from pathlib import Path

from instruments.cache_entries import merge_entries, read_entries

__all__ = ["MAX_ENTRIES", "UnitMemo"]

#: at most this many answers are kept (a lab types a few dozen units)
MAX_ENTRIES = 4096

Answer = tuple[float | None, str]


class UnitMemo:
    """What pint answered for ``(unit, dimension)``, kept in ``folder`` under a key made of
    ``key_parts`` (bytes or strings)."""

    def __init__(self, folder: Path, key_parts: Iterable[bytes | str]) -> None:
        digest = hashlib.sha256()
        for part in key_parts:
            digest.update(part if isinstance(part, bytes) else part.encode())
            digest.update(b"\0")
        self.path = folder / f"units-{digest.hexdigest()[:16]}.json"
        self._lock = threading.Lock()
        self._answers: dict[str, Answer] | None = None

    @staticmethod
    def _entry(unit: str, dimension: str) -> str:
        return f"{unit}\0{dimension}"

    def _load(self) -> dict[str, Answer]:
        if self._answers is None:
            self._answers = {}
            for entry, value in read_entries(self.path).items():
                answer = _answer(value)
                if answer is not None:
                    self._answers[entry] = answer
        return self._answers

    def recall(self, unit: str, dimension: str) -> Answer | None:
        """pint's answer for ``unit`` as ``dimension``, or ``None`` when it was never asked."""
        with self._lock:
            return self._load().get(self._entry(unit, dimension))

    def remember(self, unit: str, dimension: str, answer: Answer) -> None:
        """Keep ``answer`` (pint's) and merge it into the file (only a miss gets here)."""
        with self._lock:
            answers = self._load()
            entry = self._entry(unit, dimension)
            if answers.get(entry) == answer or len(answers) >= MAX_ENTRIES:
                return
            answers[entry] = answer
            merge_entries(self.path, {entry: list(answer)}, MAX_ENTRIES)


def _answer(value: object) -> Answer | None:
    """A stored ``[factor or null, what]`` as an answer, or ``None`` if it is not one."""
    if not (isinstance(value, list) and len(value) == 2 and isinstance(value[1], str)):
        return None
    factor, what = value
    if factor is None:
        return None, what
    if isinstance(factor, int | float) and not isinstance(factor, bool) and math.isfinite(factor):
        return float(factor), what
    return None
