"""Every case of the bad-input table (cases.py) is refused up front: exit 2, one line on
stderr naming the problem, no traceback, nothing written, no instrument opened, under 2 s and
500 MB (issue 16)."""

from __future__ import annotations

from pathlib import Path

import pytest

from .cases import CASES, Case
from .doc_table import doc_rows, row
from .runner import check_refused, run_case


def _params() -> list[object]:
    out: list[object] = []
    for case in CASES:
        marks = [pytest.mark.xfail(strict=True, reason=case.pending)] if case.pending else []
        out.append(pytest.param(case, id=case.name, marks=marks))
    return out


def test_case_names_are_unique() -> None:
    names = [c.name for c in CASES]
    assert len(names) == len(set(names))


@pytest.mark.timeout(60)
@pytest.mark.parametrize("case", _params())
def test_bad_input_is_refused_in_one_line(
    case: Case, tmp_path: Path, sources: dict[str, bytes], monkeypatch: pytest.MonkeyPatch
) -> None:
    outcome = run_case(case, tmp_path, sources, monkeypatch)
    check_refused(case, outcome)
    assert doc_rows().get(case.name) == row(case, outcome), (
        "docs/reliability.md does not show this outcome: run python -m tests.bad_inputs.doc_table"
    )
