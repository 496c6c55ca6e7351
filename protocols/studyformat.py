"""What marks a design study's output, and the error of one that cannot be used: the light part
of :mod:`protocols.studyfile`, which re-exports both. Telling a study output from a run file
(:mod:`protocols.outputfile`) needs only these, not the study schema (:mod:`protocols.study`,
pydantic): 0.15-0.18 s that every ``biafc figures`` of a run file paid."""

from __future__ import annotations

__all__ = ["FORMAT", "FORMAT_VERSION", "DamagedCellsError", "StudyFileError"]

#: the root's ``format`` attribute of a study output
FORMAT = "biafc-study"
#: the root's ``format_version`` of the layout :mod:`protocols.studyfile` writes
FORMAT_VERSION = 1


class StudyFileError(ValueError):
    """A study output that cannot be used (one line: the file and why)."""


class DamagedCellsError(StudyFileError):
    """Results of some cells fail their checksum (damaged on disk); the rest of the output
    reads. ``biafc repair`` clears them (:mod:`protocols.damaged_cells`)."""
