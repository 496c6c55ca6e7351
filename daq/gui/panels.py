"""The window's panels: bench, protocol (editor with live validation), run controls, log.

The panels hold widgets and emit intentions (signals); :class:`daq.gui.main_window.MainWindow`
does the work. Nothing here talks to instruments.
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Callable
from typing import Any

from PySide6.QtCore import Qt, QTimer, Signal
from PySide6.QtGui import QFont, QFontDatabase
from PySide6.QtWidgets import (
    QGroupBox,
    QHBoxLayout,
    QLabel,
    QLineEdit,
    QPlainTextEdit,
    QProgressBar,
    QPushButton,
    QSizePolicy,
    QTreeWidget,
    QTreeWidgetItem,
    QVBoxLayout,
    QWidget,
)

from daq.gui.views import amplitude_text
from daq.progress import format_duration

__all__ = ["BenchPanel", "LogView", "ProtocolPanel", "RunPanel", "format_duration"]


def _label_rows(values: dict[str, Any]) -> list[tuple[str, str]]:
    return [(k, str(v)) for k, v in values.items()]


class BenchPanel(QGroupBox):
    """Bench file, connect, each instrument's identity and state, safe-state button."""

    open_requested = Signal()
    connect_requested = Signal()
    safe_state_requested = Signal()
    refresh_requested = Signal()

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__("Bench", parent)
        lay = QVBoxLayout(self)
        row = QHBoxLayout()
        self.path_edit = QLineEdit()
        self.path_edit.setReadOnly(True)
        self.path_edit.setPlaceholderText("simulated bench (default)")
        self.open_button = QPushButton("Open…")
        row.addWidget(self.path_edit, 1)
        row.addWidget(self.open_button)
        lay.addLayout(row)
        row2 = QHBoxLayout()
        self.connect_button = QPushButton("Connect")
        self.refresh_button = QPushButton("Refresh")
        self.safe_button = QPushButton("Safe state")
        self.safe_button.setStyleSheet("QPushButton { color: #a00000; font-weight: bold; }")
        for b in (self.connect_button, self.refresh_button, self.safe_button):
            row2.addWidget(b)
        lay.addLayout(row2)
        self.status_label = QLabel("not connected")
        self.status_label.setWordWrap(True)
        lay.addWidget(self.status_label)
        self.tree = QTreeWidget()
        self.tree.setHeaderLabels(["instrument / field", "value"])
        self.tree.setColumnWidth(0, 170)
        lay.addWidget(self.tree, 1)
        self.open_button.clicked.connect(self.open_requested)
        self.connect_button.clicked.connect(self.connect_requested)
        self.safe_button.clicked.connect(self.safe_state_requested)
        self.refresh_button.clicked.connect(self.refresh_requested)
        self.set_connected(False)

    def set_connected(self, connected: bool, busy: bool = False) -> None:
        self.connect_button.setText("Reconnect" if connected else "Connect")
        self.connect_button.setEnabled(not busy)
        self.refresh_button.setEnabled(connected and not busy)
        self.safe_button.setEnabled(connected)

    def show_snapshot(self, snapshot: dict[str, Any]) -> None:
        """One top-level item per instrument, its fields below (nested dicts flattened)."""
        self.tree.clear()
        first = ("generator", "vibrometer", "stage", "digitiser")
        names = [n for n in first if n in snapshot] + [n for n in snapshot if n not in first]
        for name in names:
            value = snapshot[name]
            top = QTreeWidgetItem([name, "" if isinstance(value, dict) else str(value)])
            self.tree.addTopLevelItem(top)
            if isinstance(value, dict):
                for k, v in _flatten(value):
                    top.addChild(QTreeWidgetItem([k, v]))
            top.setExpanded(name in first)


def _flatten(d: dict[str, Any], prefix: str = "") -> list[tuple[str, str]]:
    out: list[tuple[str, str]] = []
    for k, v in d.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            out += _flatten(v, key + ".")
        else:
            text = str(v)
            out.append((key, text if len(text) < 120 else text[:117] + "…"))
    return out


class ProtocolPanel(QGroupBox):
    """Protocol file: its YAML text, validated as you type (the error names the field and line),
    the fields it resolves to (SI, with units), open / save, dry run."""

    open_requested = Signal()
    save_requested = Signal()
    dry_run_requested = Signal()
    text_edited = Signal(str)

    #: ms of typing quiet before the text is validated
    DEBOUNCE_MS = 250

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__("Protocol", parent)
        lay = QVBoxLayout(self)
        row = QHBoxLayout()
        self.path_edit = QLineEdit()
        self.path_edit.setReadOnly(True)
        self.path_edit.setPlaceholderText("no protocol file")
        self.open_button = QPushButton("Open…")
        self.save_button = QPushButton("Save")
        self.dry_button = QPushButton("Dry run")
        row.addWidget(self.path_edit, 1)
        for b in (self.open_button, self.save_button, self.dry_button):
            row.addWidget(b)
        lay.addLayout(row)
        self.editor = QPlainTextEdit()
        mono = QFontDatabase.systemFont(QFontDatabase.SystemFont.FixedFont)
        mono.setPointSize(max(mono.pointSize(), 9))
        self.editor.setFont(mono)
        self.editor.setLineWrapMode(QPlainTextEdit.LineWrapMode.NoWrap)
        lay.addWidget(self.editor, 3)
        self.status_label = QLabel("")
        self.status_label.setWordWrap(True)
        self.status_label.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        lay.addWidget(self.status_label)
        self.fields = QTreeWidget()
        self.fields.setHeaderLabels(["field", "value (SI)"])
        self.fields.setColumnWidth(0, 150)
        lay.addWidget(self.fields, 2)
        self._timer = QTimer(self)
        self._timer.setSingleShot(True)
        self._timer.setInterval(self.DEBOUNCE_MS)
        self._timer.timeout.connect(lambda: self.text_edited.emit(self.editor.toPlainText()))
        self.editor.textChanged.connect(self._timer.start)
        self.open_button.clicked.connect(self.open_requested)
        self.save_button.clicked.connect(self.save_requested)
        self.dry_button.clicked.connect(self.dry_run_requested)
        self.valid = False

    def set_text(self, text: str) -> None:
        self.editor.setPlainText(text)

    def validate_now(self) -> None:
        """Validate at once (skip the typing debounce)."""
        self._timer.stop()
        self.text_edited.emit(self.editor.toPlainText())

    def show_error(self, message: str) -> None:
        self.valid = False
        self.status_label.setStyleSheet("QLabel { color: #b00000; font-weight: bold; }")
        self.status_label.setText(f"✗ {message}")
        self.fields.clear()  # the last valid protocol's values are not this text's

    def show_ok(self, message: str, fields: dict[str, str]) -> None:
        self.valid = True
        self.status_label.setStyleSheet("QLabel { color: #006000; }")
        self.status_label.setText(f"✓ {message}")
        self.fields.clear()
        for k, v in fields.items():
            self.fields.addTopLevelItem(QTreeWidgetItem([k, v]))


class RunPanel(QGroupBox):
    """Start, pause, resume, abort, resume an interrupted file; progress with ETA and where."""

    start_requested = Signal()
    pause_requested = Signal()
    resume_requested = Signal()
    abort_requested = Signal()
    resume_file_requested = Signal()
    #: True while a run starts, runs or is paused: the bench and protocol wait until it ends
    active_changed = Signal(bool)

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__("Run", parent)
        lay = QVBoxLayout(self)
        row = QHBoxLayout()
        self.out_edit = QLineEdit()
        self.out_edit.setPlaceholderText("output file (default: the protocol's output pattern)")
        row.addWidget(QLabel("Output:"))
        row.addWidget(self.out_edit, 1)
        lay.addLayout(row)
        buttons = QHBoxLayout()
        self.start_button = QPushButton("▶ Start")
        self.pause_button = QPushButton("❚❚ Pause")
        self.resume_button = QPushButton("Resume")
        self.abort_button = QPushButton("■ Abort")
        self.resume_file_button = QPushButton("Resume file…")
        for b in (
            self.start_button,
            self.pause_button,
            self.resume_button,
            self.abort_button,
            self.resume_file_button,
        ):
            buttons.addWidget(b)
        lay.addLayout(buttons)
        self.progress = QProgressBar()
        self.progress.setFormat("%v / %m points")
        lay.addWidget(self.progress)
        self.where_label = QLabel("idle")
        bold = QFont(self.where_label.font())
        bold.setBold(True)
        self.where_label.setFont(bold)
        # a long final line (an unsafe end names every output to switch off) wraps: before, it
        # widened the window past the screen and hid the line's end and the buttons
        self.where_label.setWordWrap(True)
        self.where_label.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Preferred)
        self.where_label.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        lay.addWidget(self.where_label)
        self.start_button.clicked.connect(self.start_requested)
        self.pause_button.clicked.connect(self.pause_requested)
        self.resume_button.clicked.connect(self.resume_requested)
        self.abort_button.clicked.connect(self.abort_requested)
        self.resume_file_button.clicked.connect(self.resume_file_requested)
        self._blocked = False  # another task works on the instruments (set_blocked)
        self._startable = True  # the editor's protocol is valid (set_startable)
        self._bench_ok = True  # a bench file is loaded to run on (set_bench_ok)
        self.set_state("idle")

    def set_blocked(self, blocked: bool) -> None:
        """Hold Start and Resume file back while another task works on the instruments (the
        Safe state, a read of their state): a run started then drove the bench from a second
        thread."""
        self._blocked = blocked
        self.set_state(self._state)

    def set_startable(self, startable: bool) -> None:
        """Start only with a valid protocol in the editor (Resume file takes the file's)."""
        self._startable = startable
        self.set_state(self._state)

    def set_bench_ok(self, ok: bool) -> None:
        """Resume file… only with a bench to run on (a bench file that did not load, none
        loaded: before, it opened the file dialog and then refused, naming the bench's error).
        Start needs the bench too: the protocol does not validate without one."""
        self._bench_ok = ok
        self.set_state(self._state)

    @property
    def active(self) -> bool:
        """A run starts, runs or is paused."""
        return self._state in ("running", "paused", "starting")

    def set_state(self, state: str) -> None:
        """Enable the buttons that make sense in engine state ``state``."""
        self._state = state
        active = state in ("running", "paused", "starting")
        free = not active and not self._blocked
        self.start_button.setEnabled(free and self._startable)
        self.resume_file_button.setEnabled(free and self._bench_ok)
        self.pause_button.setEnabled(state == "running")
        self.resume_button.setEnabled(state == "paused")
        self.abort_button.setEnabled(active)
        self.out_edit.setEnabled(not active)
        self.active_changed.emit(active)

    def show_progress(self, d: dict[str, Any]) -> None:
        self.progress.setMaximum(int(d["total"]))
        self.progress.setValue(int(d["done"]))
        amp = float(d.get("amplitude", float("nan")))
        amp_text = amplitude_text(amp, str(d.get("amplitude_units", "")))
        self.where_label.setText(
            f"{d['direction']}  ·  amplitude {amp_text}  ·  cylinder {d['cylinder']}"
            f"  ·  elapsed {format_duration(d['elapsed_s'])}  ·  ETA {format_duration(d['eta_s'])}"
        )


def _local_now() -> dt.datetime:
    """Now in the local zone, as the window's clock reads (``time.strftime`` did the same)."""
    return dt.datetime.now().astimezone()


class LogView(QPlainTextEdit):
    """Time-stamped log lines (run events, warnings, errors).

    Each line is stamped HH:MM:SS, local time; a heading line names the date ("— 2026-11-28
    (CET) —") before the first line and again before the first line of each new day (or after
    a change of the zone's offset, summer time), so a week-long run's log says which day each
    line is from. ``now`` is the clock (a test injects one)."""

    def __init__(
        self, parent: QWidget | None = None, now: Callable[[], dt.datetime] = _local_now
    ) -> None:
        super().__init__(parent)
        self.setReadOnly(True)
        self.setMaximumBlockCount(5000)
        self._now = now
        self._day: tuple[dt.date, dt.timedelta | None] | None = None
        #: the logged lines, one per :meth:`add`, without the date headings (a heading between
        #: two lines would move what a caller finds at ``lines[-2]`` across midnight)
        self.lines: list[str] = []

    def add(self, message: str, level: str = "info") -> None:
        when = self._now()
        day = (when.date(), when.utcoffset())
        if day != self._day:
            self._day = day
            zone = when.tzname() or when.strftime("UTC%z")
            self.appendHtml(
                f'<span style="color:#606060">— {when:%Y-%m-%d} ({_html(zone)}) —</span>'
            )
        line = f"{when:%H:%M:%S} {level:7s} {message}"
        self.lines.append(line)
        if level in ("warning", "error"):
            colour = "#b00000" if level == "error" else "#a06000"
            # white-space:pre: rich text would collapse the padding after the level
            style = f"color:{colour}; white-space:pre"
            self.appendHtml(f'<span style="{style}">{_html(line)}</span>')
        else:
            self.appendPlainText(line)


def _html(text: str) -> str:
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
