"""How a run ends, as an exit status and one last line: the same words in the CLI and the GUI.

Exit statuses of ``run_protocol`` (and of every refusal in ``biafc``):

====  ====================================================================================
0     complete: every point measured, safe state confirmed
1     the run failed or was aborted (by the GUI, SIGTERM); safe state confirmed
2     the request was refused before anything moved (bad input, refused resume, file in use)
3     unsafe: the safe state could not be confirmed by reading it back; switch off by hand
4     finished with failed points (marked in the file); ``--resume`` re-measures them
130   interrupted by Ctrl-C (SIGINT); safe state confirmed
====  ====================================================================================

"unsafe" wins over every other outcome: whatever else happened, the person at the bench must
first switch the named output off.
"""

from __future__ import annotations

from enum import IntEnum
from typing import Any

__all__ = [
    "ExitCode",
    "counts_text",
    "exit_code",
    "final_line",
    "outcome_text",
    "unsafe_instruction",
]


class ExitCode(IntEnum):
    """Exit statuses of ``run_protocol`` (documented in the README)."""

    COMPLETE = 0
    FAILED = 1
    REFUSED = 2
    UNSAFE = 3
    POINTS_FAILED = 4
    INTERRUPTED = 130


def exit_code(result: Any, *, sigint: bool = False) -> ExitCode:
    """The exit status of a :class:`daq.engine.RunResult` (``sigint``: ended by Ctrl-C)."""
    status = str(result.status)
    if status == "unsafe":
        return ExitCode.UNSAFE
    if status == "refused":
        return ExitCode.REFUSED
    if status == "complete":
        return ExitCode.COMPLETE
    if status == "aborted" and sigint:
        return ExitCode.INTERRUPTED
    if status == "failed" and getattr(result, "points_failed_only", False):
        return ExitCode.POINTS_FAILED
    return ExitCode.FAILED


def unsafe_instruction(unconfirmed: list[str] | tuple[str, ...]) -> str:
    """What the person must do by hand when the safe state is not confirmed: the piezo
    amplifier as the alternative where a generator output is among them, the stage's
    controller where only the stage is."""
    if any("generator" in u for u in unconfirmed):
        where = " (or switch the piezo amplifier off) before touching the chain"
    else:
        where = " before reaching into the stage's travel"
    return "SWITCH OFF BY HAND: " + "; ".join(unconfirmed) + where


def counts_text(result: Any) -> str:
    """``"measured now 25, already in the file 6, failed 0 (of 31)"``."""
    return (
        f"measured now {result.n_measured_now}, already in the file {result.n_already}, "
        f"failed {result.n_failed} (of {result.n_points})"
    )


def final_line(result: Any) -> str:
    """The last line a run prints (the GUI shows the same text)."""
    status = str(result.status)
    safe = ""
    if getattr(result, "safe_state_s", None) is not None and status != "refused":
        safe = f"; safe state confirmed in {result.safe_state_s:.1f} s"
    if status == "unsafe":
        return outcome_text(result)
    if status == "refused":
        return f"run refused: {result.reason}"
    if status == "complete":
        return (
            f"complete: {result.n_done} points in {result.wall_s:.1f} s "
            f"({counts_text(result)}){safe} -> {result.path}"
        )
    return f"{outcome_text(result)}; {counts_text(result)}{safe} ({_file_words(result)})"


def _file_words(result: Any) -> str:
    """Where the points are: the file, or that none was written (a run ended before it made
    its file; a resume before it opened it: the file is as it was)."""
    if getattr(result, "file_written", True):
        return f"file {result.path}"
    if getattr(result, "resumed", False):
        return f"file {result.path} not opened: unchanged"
    return f"no file written: {result.path} was not made"


def outcome_text(result: Any) -> str:
    """What happened, in the words the file keeps (root attribute ``outcome``) and the last
    line begins with: ``"complete"``, ``"finished with failed points: ..."`` (exit 4, which
    the file's ``status`` "failed" shares with a run that failed), ``"run failed: <reason>"``,
    ``"run aborted: ..."``, ``"run UNSAFE (<reason>): SWITCH OFF BY HAND: ..."``."""
    status = str(result.status)
    if status == "complete":
        return "complete"
    if status == "unsafe":  # first (failed points before an unsafe end hid it); with what to
        # switch off, as the last line says it
        why = f" ({result.reason})" if result.reason else ""
        unconfirmed = tuple(getattr(result, "unconfirmed", ()) or ())
        return f"run UNSAFE{why}" + (f": {unsafe_instruction(unconfirmed)}" if unconfirmed else "")
    if getattr(result, "points_failed_only", False):
        return str(result.reason)
    return f"run {status}: {result.reason}" if result.reason else f"run {status}"
