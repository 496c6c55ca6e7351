"""A biafc output of either kind, a run file (:mod:`protocols.runfile`) or a design study's
output (:mod:`protocols.studyfile`), told apart and read through one open of the file.

Each open of a file that is truncated or damaged while its consistency flags are set (a writer
killed mid-write) waits before it refuses: :data:`protocols.hdf5probe.LIVE_GRACE_S` (0.5 s) for
a live writer to catch up, or the bounded SWMR retry (about 0.27 s,
:mod:`protocols.swmr_read`). Asking "is it a study?" and then reading the file as a run paid
that wait twice; :func:`read_output` pays it once.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from protocols.runfile import RunData, one_line_errors, open_for_reading, read_open_run
from protocols.studyformat import FORMAT as STUDY_FORMAT
from protocols.studyformat import StudyFileError

if TYPE_CHECKING:
    from protocols.studyfile import StudyData

__all__ = ["read_output"]


def read_output(path: str | Path, *, spectra: bool = True) -> RunData | StudyData:
    """The whole file ``path``: :class:`StudyData` when its root says it is a study output
    (``spectra``: with its spectra), else :class:`RunData`. A missing file is a
    :class:`FileNotFoundError`; one that opens as no HDF5 file, or is no run file, or is a run
    file damaged inside, a :class:`~protocols.runfile.RunFileError` (one line, as
    :func:`~protocols.runfile.read_run`); a study output that does not read, a
    :class:`StudyFileError` (as :func:`~protocols.studyfile.read_study`)."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"run file {path} does not exist")
    with one_line_errors(path, passing=(StudyFileError,)), open_for_reading(path) as f:
        if f.attrs.get("format") == STUDY_FORMAT:
            from protocols.studyfile import read_open_study  # the study schema: studies only

            return read_open_study(path, f, spectra=spectra)
        return read_open_run(path, f)
