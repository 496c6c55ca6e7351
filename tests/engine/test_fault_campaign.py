"""The short form of the fault campaign (``python -m benchmarks faults``), run in CI: injected
faults at three moments, a SIGKILL and a Ctrl-C mid-run, each row end to end (exit status, last
line, the emulated generator's outputs, points kept with plain h5py, resume bit for bit)."""

from __future__ import annotations

from pathlib import Path

from benchmarks.faults import BEGIN, END, campaign, markdown, write_doc


def test_the_short_fault_campaign_passes_every_row(tmp_path: Path) -> None:
    rows = campaign(short=True, tmp=tmp_path)
    assert len(rows) == 5
    failed = [r for r in rows if not r.ok]
    assert not failed, "\n".join(f"{r.trial} {r.moment}: {r}" for r in failed)
    silent = rows[0]
    assert silent.exit == 3 and "SWITCH OFF BY HAND" in silent.last_line
    assert "ON, reported unsafe" in silent.safe_state
    sigint = rows[-1]
    assert sigint.exit == 130 and sigint.safe_s is not None and sigint.safe_s < 2.0
    doc = tmp_path / "reliability.md"
    doc.write_text("# Reliability\n\n## Bad inputs\n\nkept\n")
    write_doc(markdown(rows), doc)
    write_doc(markdown(rows), doc)  # replaces its own section, keeps the others
    text = doc.read_text()
    assert text.count(BEGIN) == 1 and text.count(END) == 1 and "## Bad inputs" in text
    assert "5 of 5 rows pass" in text and str(tmp_path) not in text
