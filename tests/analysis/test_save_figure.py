"""``analysis.plots.style.save_figure``: both formats from one layout."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from matplotlib.layout_engine import ConstrainedLayoutEngine

from analysis.plots.style import FORMATS, new_figure, save_figure, style


def _figure() -> Any:
    """Two axes, a label, an image and a title the constrained layout has to make room for."""
    with style():
        fig, axes = new_figure(1, 2)
        axes[0, 0].plot([0.0, 1.0, 4.0])
        axes[0, 0].set_ylabel("velocity (m/s)")
        axes[0, 1].imshow([[0.0, 1.0], [2.0, 3.0]])
        axes[0, 1].set_title("a title that the layout has to make room for")
    return fig


def _counted(monkeypatch: pytest.MonkeyPatch, cls: type, name: str) -> list[Any]:
    """The calls of method ``cls.name`` from now on (their second argument each)."""
    calls: list[Any] = []
    method = getattr(cls, name)

    def counted(self: Any, arg: Any) -> Any:
        calls.append(arg)
        return method(self, arg)

    monkeypatch.setattr(cls, name, counted)
    return calls


def test_save_figure_lays_out_once_for_every_format(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The constrained layout runs once for the PNG and the PDF together (it ran once per
    format before, about a fifth of ``biafc figures``), both files are written, and the
    figure keeps its layout engine for whatever the caller does next."""
    calls = _counted(monkeypatch, ConstrainedLayoutEngine, "execute")
    fig = _figure()
    engine = fig.get_layout_engine()
    paths = save_figure(fig, tmp_path, "one_layout")
    assert [p.suffix for p in paths] == [f".{fmt}" for fmt in FORMATS]
    assert all(p.stat().st_size > 0 for p in paths)
    assert len(calls) == 1
    assert fig.get_layout_engine() is engine


def test_save_figure_draws_each_file_once(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """One draw per file: ``savefig`` draws a figure with a layout engine twice (a layout draw
    with rendering off, then the rendering), four draws for the two formats before."""
    from matplotlib.figure import Figure

    draws = _counted(monkeypatch, Figure, "draw")
    fig = _figure()
    canvas, dpi = fig.canvas, fig.dpi
    save_figure(fig, tmp_path, "once")
    assert len(draws) == len(FORMATS)
    assert fig.canvas is canvas and fig.dpi == dpi


def test_save_figure_writes_what_savefig_writes(tmp_path: Path) -> None:
    """The PNG byte for byte as ``savefig`` at the style's dpi writes it; the PDF too, but for
    its creation date."""
    import re

    from analysis.plots.style import RC

    paths = save_figure(_figure(), tmp_path / "one_draw", "f")
    with style():
        ref = _figure()
        ref.savefig(tmp_path / "f.png", dpi=RC["savefig.dpi"])
        ref.set_layout_engine("none")  # as save_figure: the PDF keeps the PNG's layout
        ref.savefig(tmp_path / "f.pdf", dpi=RC["savefig.dpi"])
    png, pdf = (p.read_bytes() for p in paths)
    assert png == (tmp_path / "f.png").read_bytes()
    undated = re.compile(rb"/CreationDate \(D:[^)]*\)")
    assert undated.sub(b"", pdf) == undated.sub(b"", (tmp_path / "f.pdf").read_bytes())
