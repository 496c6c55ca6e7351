"""A stdout that notes, for each line printed, the PNG files in a folder at that moment: what
was written before a line was printed (``biafc figures``, ``biafc compare``)."""

from __future__ import annotations

from pathlib import Path


class PrintedLines:
    """Put in place of ``sys.stdout``; ``lines`` holds ``(line, {png stems in folder})``."""

    def __init__(self, folder: Path) -> None:
        self.folder, self._buf = folder, ""
        self.lines: list[tuple[str, set[str]]] = []

    def write(self, text: str) -> int:
        self._buf += text
        while "\n" in self._buf:
            line, self._buf = self._buf.split("\n", 1)
            pngs = {p.stem for p in self.folder.glob("*.png")} if self.folder.exists() else set()
            self.lines.append((line, pngs))
        return len(text)

    def flush(self) -> None:
        pass
