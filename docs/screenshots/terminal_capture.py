"""Terminal captures for the docs: run a command in a real terminal (tmux), take the screen as
it looks (colours included) at chosen moments, and write each as PNG (rich draws it as SVG, Qt
renders that).

    python docs/screenshots/terminal_capture.py NAME SECONDS[,SECONDS...] -- COMMAND...

e.g. the progress display of run_protocol mid-run and at the end::

    cd "$(mktemp -d)" && PATH="$VENV/bin:$PATH" python $REPO/docs/screenshots/terminal_capture.py \\
        run_protocol 4,30 -- run_protocol biafc_sweep --out runs/biafc_sweep.h5

(run from an empty folder, with the command on the PATH, so no machine path shows); it
writes ``docs/screenshots/run_protocol_4s.png`` and ``run_protocol_end.png`` (the last moment
is taken when the command has ended). Needs tmux; the PNG is rendered with Qt's SVG module.
"""

from __future__ import annotations

import os
import shlex
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
WIDTH, HEIGHT = 124, 8


#: a tmux server of our own: the command inherits this process's environment and folder
TMUX = ["tmux", "-L", f"capture{os.getpid()}"]


def _capture(session: str) -> str:
    return subprocess.run(
        [*TMUX, "capture-pane", "-e", "-p", "-t", session], capture_output=True, text=True,
        check=True,
    ).stdout.rstrip("\n")  # fmt: skip


def _render(ansi: str, title: str, stem: Path) -> None:
    from rich.console import Console
    from rich.text import Text

    console = Console(record=True, width=WIDTH, force_terminal=True, file=open("/dev/null", "w"))
    console.print(Text.from_ansi(ansi))
    svg = stem.with_suffix(".svg")
    console.save_svg(str(svg), title=title)
    _svg_to_png(svg, stem.with_suffix(".png"))
    svg.unlink()


def _svg_to_png(svg: Path, png: Path, scale: float = 1.5) -> None:
    """Render an SVG to PNG with Qt (offscreen), white-free: the SVG's own background."""
    import os

    os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
    from PySide6.QtCore import QByteArray, QRectF
    from PySide6.QtGui import QGuiApplication, QImage, QPainter
    from PySide6.QtSvg import QSvgRenderer

    _app = QGuiApplication.instance() or QGuiApplication([])
    # rich names a web font (Fira Code) Qt cannot fetch: a monospaced font keeps the columns
    text = svg.read_text().replace("Fira Code, monospace", "DejaVu Sans Mono, monospace")
    text = text.replace("<text ", '<text font-family="DejaVu Sans Mono" xml:space="preserve" ')
    text = text.replace("&#160;", " ")  # Qt draws rich's no-break spaces with no width
    renderer = QSvgRenderer(QByteArray(text.encode()))
    size = renderer.defaultSize()
    image = QImage(int(size.width() * scale), int(size.height() * scale), QImage.Format_ARGB32)
    image.fill(0)
    painter = QPainter(image)
    renderer.render(painter, QRectF(0, 0, image.width(), image.height()))
    painter.end()
    if not image.save(str(png)):
        raise OSError(f"cannot write {png}")


def main(argv: list[str]) -> int:
    if "--" not in argv or len(argv) < 4:
        print(__doc__, file=sys.stderr)
        return 2
    name, times = argv[0], [float(t) for t in argv[1].split(",")]
    command = argv[argv.index("--") + 1 :]
    session = f"capture{int(time.time())}"
    shell = f"{shlex.join(command)}; echo; echo '[exit '$?']'; sleep 3600"
    subprocess.run([*TMUX, "new-session", "-d", "-s", session, "-x", str(WIDTH), "-y",
                    str(HEIGHT), shell], check=True)  # fmt: skip
    t0 = time.monotonic()
    title = "$ " + " ".join(Path(command[0]).name if i == 0 else c for i, c in enumerate(command))
    try:
        for k, t in enumerate(times):
            last = k == len(times) - 1
            while time.monotonic() - t0 < t:
                if last and "[exit " in _capture(session):
                    break
                time.sleep(0.1)
            screen = _capture(session)
            label = "end" if last else f"{t:g}s"
            lines = [ln for ln in screen.splitlines() if "[exit " not in ln]
            _render("\n".join(lines).rstrip(), title, HERE / f"{name}_{label}")
            print(f"written {HERE / f'{name}_{label}.png'}")
    finally:
        subprocess.run([*TMUX, "kill-server"], check=False)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
