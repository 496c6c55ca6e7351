"""docs/reliability.md lists exactly the cases of cases.py, in order; the rows of cases that
run are checked against their actual one line in test_cases.py."""

from __future__ import annotations

from .cases import CASES
from .doc_table import current_table, doc_rows, row
from .runner import Outcome


def test_doc_table_lists_the_cases_in_order() -> None:
    table = current_table()
    assert table is not None, "docs/reliability.md lacks the bad-inputs table markers"
    rows = doc_rows()
    assert list(rows) == [c.name for c in CASES], (
        "docs/reliability.md is out of date: run python -m tests.bad_inputs.doc_table"
    )


def test_pending_rows_say_what_is_expected() -> None:
    rows = doc_rows()
    for case in CASES:
        if case.pending:
            assert rows[case.name] == row(case, Outcome(None, "", "", "", 0, 0, False, [])), (
                "run python -m tests.bad_inputs.doc_table"
            )
