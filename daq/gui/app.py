"""``biafc-gui [--bench BENCH.yaml] [--protocol PROTOCOL.yaml] [--run RUN.h5] [--connect]``:
the bench window."""

from __future__ import annotations

import argparse
import importlib.util
import os
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

__all__ = [
    "add_arguments",
    "check_paths",
    "display_problem",
    "main",
    "run_window",
    "xcb_plugin_problem",
]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--bench", type=Path, default=None, help="bench file (default: the simulated bench)"
    )
    parser.add_argument(
        "--protocol",
        type=Path,
        default=None,
        help="protocol file to open (a path, or the name of a shipped protocol, e.g. smoke)",
    )
    parser.add_argument("--run", type=Path, default=None, help="run file to browse")
    parser.add_argument("--connect", action="store_true", help="connect the bench at start")
    from daq.logsetup import add_verbosity_arguments

    add_verbosity_arguments(parser)


def check_paths(args: argparse.Namespace) -> str | None:
    """The first missing file named on the command line, as a one-line message, or None.

    ``--protocol`` takes the name of a shipped protocol as ``run_protocol`` does (``smoke``,
    ``ltr_highamp.yaml``); ``args.protocol`` is replaced by the file found."""
    from protocols.schema import resolve_protocol_path, shipped_protocols

    if args.protocol is not None:
        args.protocol = resolve_protocol_path(args.protocol)
        if not Path(args.protocol).is_file():
            names = ", ".join(sorted(shipped_protocols()))
            return f"--protocol: {args.protocol} does not exist (shipped protocols: {names})"
    for flag in ("bench", "run"):
        p = getattr(args, flag)
        if p is not None and not Path(p).is_file():
            return f"--{flag}: {p} does not exist"
    return None


def xcb_plugin_problem() -> str | None:
    """Why Qt's X11 platform plugin (``libqxcb.so``, PySide6's own) cannot load here, in one
    line saying what to install, or None. It needs X11 libraries of the system that a desktop
    may lack (``libxcb-cursor0`` since Qt 6.5, ``libxcb-icccm4``...); Qt then aborted the
    process (status 134) with a long message naming only the first, and that only in part."""
    import ctypes

    spec = importlib.util.find_spec("PySide6")
    if spec is None or spec.origin is None:
        return None
    plugin = Path(spec.origin).parent / "Qt" / "plugins" / "platforms" / "libqxcb.so"
    if not plugin.is_file():
        return None
    try:
        ctypes.CDLL(str(plugin))
    except OSError as exc:
        why = (str(exc).splitlines() or ["cannot load"])[0].replace(f"{plugin}: ", "")
        return (
            f"Qt's X11 platform plugin cannot load ({why}): install the X11 libraries Qt 6 "
            "needs (Debian, Ubuntu: sudo apt install libxcb-cursor0 libxcb-icccm4 "
            "libxcb-keysyms1 libxcb-image0 libxcb-render-util0 libxkbcommon-x11-0 "
            "libxcb-xinerama0 libxcb-shape0), or set QT_QPA_PLATFORM=offscreen to run it "
            "without a screen"
        )
    return None


def display_problem(
    env: dict[str, str] | None = None,
    platform: str | None = None,
    xcb_problem: Callable[[], str | None] = xcb_plugin_problem,
) -> str | None:
    """Why the window cannot open here (one line saying what to do), or None.

    On Linux Qt's default platform (xcb) needs an X display (``DISPLAY``) or Wayland
    (``WAYLAND_DISPLAY``); without one Qt aborts the process with a long xcb message. With a
    display, its plugin must load (``xcb_problem``: :func:`xcb_plugin_problem`). An explicit
    ``QT_QPA_PLATFORM`` other than xcb (offscreen, wayland, vnc...) is left to Qt."""
    env = dict(os.environ) if env is None else env
    platform = sys.platform if platform is None else platform
    if not platform.startswith("linux"):
        return None
    qpa = env.get("QT_QPA_PLATFORM", "").split(":")[0]
    if qpa and qpa != "xcb":
        return None
    if not qpa and env.get("WAYLAND_DISPLAY"):
        return None
    if env.get("DISPLAY"):
        return xcb_problem()
    return (
        "no display to open the window on (DISPLAY is not set): log in with ssh -X (or -Y) to "
        "show it here, or set QT_QPA_PLATFORM=offscreen to run it without a screen"
    )


def run_window(args: argparse.Namespace) -> int:
    """Open the window and run the Qt event loop; returns the exit code."""
    from PySide6.QtWidgets import QApplication

    from daq.cli.console_close import hold_console_close
    from daq.gui.display_lost import watch_display
    from daq.gui.main_window import MainWindow
    from daq.gui.stop_signals import close_on_stop_signals
    from daq.logsetup import configure, verbosity
    from protocols.left_open import exit_leaving_them, files_left_open

    configure(verbosity(args))
    app = QApplication.instance() or QApplication(sys.argv[:1])
    app.setApplicationName("biafc-lab")
    win = MainWindow(args.bench, args.protocol)
    if args.run is not None:
        win.open_run_file(args.run)
    if args.connect:
        win.connect_bench()
    win.show()
    hold = hold_console_close(win.console_closed)  # Windows: a closed console aborts the run
    unwatch = watch_display(win.display_lost)  # the display gone (ssh -X): aborts the run
    unsignal = close_on_stop_signals(win.stop_signal)  # SIGTERM, SIGHUP, Ctrl-C: as Close
    code = int(app.exec()) or int(getattr(win, "exit_status", 0))  # a run aborted by the close
    unsignal()
    unwatch()
    if hold is not None:
        hold.remove()
    if files_left_open():  # a failed write on a full disk: HDF5's clean-up crashes the exit
        exit_leaving_them(code)
    return code


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="biafc-gui", description="The biafc-lab bench window.")
    add_arguments(parser)
    args = parser.parse_args(argv)
    err = check_paths(args) or display_problem()
    if err is not None:
        print(f"biafc-gui: error: {err}", file=sys.stderr)
        return 2
    return run_window(args)


if __name__ == "__main__":
    sys.exit(main())
