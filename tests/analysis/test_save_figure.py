"""``analysis.plots.style.save_figure``: both formats from one layout."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from matplotlib.layout_engine import ConstrainedLayoutEngine

from analysis.plots.style import FORMATS, new_figure, save_figure, style


def test_save_figure_lays_out_once_for_every_format(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The constrained layout runs once for the PNG and the PDF together (it ran once per
    format before, about a fifth of ``biafc figures``), both files are written, and the
    figure keeps its layout engine for whatever the caller does next."""
    calls = []
    execute = ConstrainedLayoutEngine.execute

    def counted(self: ConstrainedLayoutEngine, fig: Any) -> Any:
        calls.append(fig)
        return execute(self, fig)

    monkeypatch.setattr(ConstrainedLayoutEngine, "execute", counted)
    with style():
        fig, axes = new_figure(1, 2)
        axes[0, 0].plot([0.0, 1.0, 4.0])
        axes[0, 0].set_ylabel("velocity (m/s)")
        axes[0, 1].set_title("a title that the layout has to make room for")
    engine = fig.get_layout_engine()
    paths = save_figure(fig, tmp_path, "one_layout")
    assert [p.suffix for p in paths] == [f".{fmt}" for fmt in FORMATS]
    assert all(p.stat().st_size > 0 for p in paths)
    assert len(calls) == 1
    assert fig.get_layout_engine() is engine
