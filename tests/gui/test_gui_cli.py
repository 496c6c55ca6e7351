"""``biafc gui`` / ``biafc-gui`` on the command line: shipped protocol names, and a machine
without a display (one line saying what to do instead of Qt's xcb abort)."""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from daq.cli import biafc
from daq.gui import app


def test_gui_accepts_a_shipped_protocol_name(monkeypatch: pytest.MonkeyPatch) -> None:
    seen: list[argparse.Namespace] = []
    monkeypatch.setattr(app, "run_window", lambda args: seen.append(args) or 0)
    assert biafc.main(["gui", "--protocol", "smoke"]) == 0
    assert Path(seen[0].protocol).name == "smoke.yaml"
    assert Path(seen[0].protocol).is_file()
    assert app.main(["--protocol", "ltr_highamp.yaml"]) == 0
    assert Path(seen[1].protocol).name == "ltr_highamp.yaml"


def test_gui_unknown_protocol_lists_the_shipped_ones(
    monkeypatch: pytest.MonkeyPatch, capsys: Any
) -> None:
    monkeypatch.setattr(app, "run_window", lambda args: 0)
    assert biafc.main(["gui", "--protocol", "smok"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "--protocol: smok does not exist" in err and "smoke" in err


@pytest.mark.parametrize(
    ("env", "platform", "problem"),
    [
        ({}, "linux", True),
        ({"QT_QPA_PLATFORM": "xcb"}, "linux", True),
        ({"QT_QPA_PLATFORM": "xcb", "WAYLAND_DISPLAY": "wayland-0"}, "linux", True),
        ({"DISPLAY": ":0"}, "linux", False),
        ({"WAYLAND_DISPLAY": "wayland-0"}, "linux", False),
        ({"QT_QPA_PLATFORM": "offscreen"}, "linux", False),
        ({}, "win32", False),
        ({}, "darwin", False),
    ],
)
def test_display_problem(env: dict[str, str], platform: str, problem: bool) -> None:
    why = app.display_problem(env, platform, xcb_problem=lambda: None)
    assert (why is not None) == problem
    if why:
        assert "QT_QPA_PLATFORM=offscreen" in why and "ssh -X" in why


def test_an_x11_plugin_that_cannot_load_is_one_line_naming_what_to_install(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A desktop without the X11 libraries Qt 6 needs: Qt aborted the process (status 134)
    after a long message that named libxcb-cursor0 only; the library missing first was
    libxcb-icccm4 here."""
    import ctypes

    def missing(name: str, *args: Any, **kw: Any) -> Any:
        if name.endswith("libqxcb.so"):
            raise OSError(f"{name}: libxcb-icccm.so.4: cannot open shared object file")
        return real(name, *args, **kw)

    real = ctypes.CDLL
    monkeypatch.setattr(ctypes, "CDLL", missing)
    import PySide6

    if not (Path(PySide6.__file__).parent / "Qt/plugins/platforms/libqxcb.so").is_file():
        pytest.skip("this PySide6 has no X11 platform plugin (libqxcb.so)")
    why = app.display_problem({"DISPLAY": ":0"}, "linux")
    assert why is not None and "\n" not in why
    assert "libxcb-icccm.so.4: cannot open shared object file" in why
    assert "libxcb-cursor0" in why and "QT_QPA_PLATFORM=offscreen" in why
    assert app.display_problem({"DISPLAY": ":0", "QT_QPA_PLATFORM": "offscreen"}, "linux") is None
    monkeypatch.setattr(ctypes, "CDLL", real)
    loads = app.xcb_plugin_problem()
    assert loads is None or "cannot load" in loads  # this machine's own answer, one line


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="xcb is Linux's")
@pytest.mark.parametrize(
    "cmd",
    [
        ["-c", "from daq.cli.biafc import main; raise SystemExit(main(['gui']))"],
        ["-c", "from daq.gui.app import main; raise SystemExit(main([]))"],
    ],
)
def test_gui_without_a_display_says_what_to_do(cmd: list[str]) -> None:
    env = {
        k: v
        for k, v in os.environ.items()
        if k not in ("DISPLAY", "WAYLAND_DISPLAY", "QT_QPA_PLATFORM")
    }
    proc = subprocess.run(
        [sys.executable, *cmd], env=env, capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert "no display" in lines[0] and "ssh -X" in lines[0]
    assert "QT_QPA_PLATFORM=offscreen" in lines[0]
