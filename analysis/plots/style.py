"""Shared look of the figures and how they are saved (PNG and PDF).

Figures are ``matplotlib.figure.Figure`` objects drawn without pyplot, so no backend is chosen
or changed (the GUI's Qt backend is left alone) and no figure is kept in a global registry.
"""

from __future__ import annotations

from collections.abc import Sequence
from contextlib import AbstractContextManager
from pathlib import Path
from typing import Any, cast

import matplotlib
import numpy as np
from matplotlib import patheffects
from matplotlib.axes import Axes
from matplotlib.colors import Colormap
from matplotlib.figure import Figure
from matplotlib.patches import Patch, Rectangle
from numpy.typing import NDArray

from analysis.display import amplitude_label, amplitude_scale

__all__ = [
    "DARK_EDGE",
    "FAILED_COLOUR",
    "FORMATS",
    "GAP_LABEL",
    "RC",
    "VERDICT_KINDS",
    "add_gap_background",
    "amplitude_label",
    "amplitude_scale",
    "cell_edges",
    "gap_legend_handle",
    "masked_cmap",
    "new_figure",
    "plot_by_verdict",
    "save_figure",
    "style",
    "verdict_kind",
    "verdict_marker",
]

#: formats every figure is written in
FORMATS: tuple[str, ...] = ("png", "pdf")
#: path effects for a white line on a dark map: a dark edge keeps it (and its legend sample,
#: on the legend's light frame, where it was invisible) visible on either background
DARK_EDGE = [patheffects.withStroke(linewidth=2.6, foreground="0.15")]
#: legend text of the hatched "not measured" background
GAP_LABEL = "failed or not measured"  # both leave NaN: a failed point is not "not measured"
#: the colour of a mark on something that failed (a study's failed cells)
FAILED_COLOUR = "crimson"

RC: dict[str, Any] = {
    "font.size": 11,
    "axes.titlesize": 11,
    "axes.labelsize": 11,
    "xtick.labelsize": 10,
    "ytick.labelsize": 10,
    "legend.fontsize": 9,
    "figure.dpi": 100,
    "savefig.dpi": 150,
    "axes.grid": False,
    "image.cmap": "viridis",
}


def new_figure(
    nrows: int = 1,
    ncols: int = 1,
    *,
    figsize: tuple[float, float] = (7.0, 4.5),
    **kwargs: Any,
) -> tuple[Figure, NDArray[Any]]:
    """A figure (not attached to pyplot's state) and its axes as a 2-D array ``[nrows, ncols]``.

    Call inside :func:`style` so that fonts and sizes apply.
    """
    fig = Figure(figsize=figsize, layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False, **kwargs)
    return fig, axes


def style() -> AbstractContextManager[None]:
    """Context in which a figure is drawn: the shared fonts and sizes (``RC``)."""
    return matplotlib.rc_context(cast(Any, RC))


def save_figure(fig: Figure, out_dir: str | Path, name: str) -> list[Path]:
    """Write ``fig`` as ``out_dir/name.png`` and ``.pdf``; returns the paths.

    One draw per file. ``Figure.savefig`` draws a figure that has a layout engine twice: once
    with rendering off, to lay it out, and once to render. Here the first format's draw lays
    the figure out (``Figure.draw`` runs the engine), and the other formats keep its positions.
    The layout (constrained: every tick label measured) had differed between PNG and PDF by at
    most 0.3 pt. The files are byte for byte those of ``savefig``, except for the PDF's creation
    date. ``biafc figures`` on the ``ltr_highamp`` run: 4.04 s against 4.53 s through ``savefig``
    with one layout (medians of 12 interleaved pairs; docs/performance.md). The figure's layout
    engine, dpi and canvas are restored afterwards."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    engine, dpi, canvas = fig.get_layout_engine(), fig.dpi, fig.canvas
    try:
        with matplotlib.rc_context(cast(Any, RC)):
            fig.dpi = RC["savefig.dpi"]
            for fmt in FORMATS:
                p = out / f"{name}.{fmt}"
                _print(fig, p, fmt)
                paths.append(p)
                fig.set_layout_engine("none")  # the next formats keep this layout
    finally:
        fig.set_layout_engine(engine)
        fig.dpi = dpi
        fig.set_canvas(canvas)
    return paths


def _print(fig: Figure, path: Path, fmt: str) -> None:
    """Draw ``fig`` once into ``path`` as ``fmt`` (one of :data:`FORMATS`) on that format's own
    canvas, as ``savefig`` does after its layout draw (animated artists drawn too)."""
    from matplotlib.backend_bases import FigureCanvasBase

    canvas: FigureCanvasBase
    if fmt == "png":
        from matplotlib.backends.backend_agg import FigureCanvasAgg

        canvas = FigureCanvasAgg(fig)
    elif fmt == "pdf":
        from matplotlib.backends.backend_pdf import FigureCanvasPdf

        canvas = FigureCanvasPdf(fig)
    else:
        raise ValueError(f"figure format {fmt!r}: expected one of {', '.join(FORMATS)}")
    # as savefig sets it while it prints (private, not in the stubs): animated artists are drawn
    canvas._is_saving = True  # type: ignore[union-attr]
    getattr(canvas, f"print_{fmt}")(path)


def masked_cmap(name: str = "viridis") -> Colormap:
    """A colormap whose NaN ("bad") colour is transparent, so the gap background shows."""
    return matplotlib.colormaps[name].with_extremes(bad=(0.0, 0.0, 0.0, 0.0))


def add_gap_background(ax: Axes) -> None:
    """Grey hatched background: wherever nothing is drawn (NaN, unmeasured), it shows."""
    ax.add_patch(
        Rectangle(
            (0, 0),
            1,
            1,
            transform=ax.transAxes,
            facecolor="0.88",
            edgecolor="0.6",
            hatch="//",
            linewidth=0,
            zorder=-10,
        )
    )


def gap_legend_handle() -> Patch:
    """Legend entry for the hatched background."""
    return Patch(facecolor="0.88", edgecolor="0.6", hatch="//", label=GAP_LABEL)


#: how far into the axes each direction's crosses sit (both visible at one amplitude)
MISSING_AT = {"ltr": 0.03, "rtl": 0.09}


def mark_missing(
    ax: Axes,
    positions: Sequence[float] | NDArray[Any],
    colour: str,
    *,
    along: str = "x",
    label: str | None = GAP_LABEL,
    marker: str = "x",
    at: float = 0.03,
) -> None:
    """Crosses for values a figure cannot draw (a failed or unmeasured point): at ``positions``
    along the x axis, at the bottom edge of the axes (``along="x"``), or along the y axis, at
    the left edge (``"y"``), ``at`` that fraction of the axes in; so a failed amplitude shows
    as a cross, not as a silent gap."""
    from matplotlib.transforms import blended_transform_factory

    pos = np.asarray(positions, dtype=np.float64)
    if pos.size == 0:
        return
    edge = np.full(pos.size, at)
    if along == "x":
        tr = blended_transform_factory(ax.transData, ax.transAxes)
        xs, ys = pos, edge
    else:
        tr = blended_transform_factory(ax.transAxes, ax.transData)
        xs, ys = edge, pos
    ax.plot(xs, ys, marker, color=colour, ms=8, mew=2, ls="none", transform=tr,
            clip_on=False, zorder=6, label=label)  # fmt: skip


#: how a far-end line's conversion verdict (:func:`analysis.summary.conversion_verdict`, through
#: :func:`analysis.summary.summary_rows`) is drawn, in drawing order: filled in its colour where
#: it converted, hollow in its colour where the run cannot tell, hollow grey where it did not
VERDICT_KINDS = ("converted", "undetermined", "not converted")


def verdict_kind(verdict: str) -> str:
    """Which of :data:`VERDICT_KINDS` a summary row's ``conversion`` verdict is drawn as."""
    from analysis.summary import is_conversion

    if is_conversion(verdict):
        return "converted"
    return "undetermined" if verdict == "undetermined" else "not converted"


def verdict_marker(kind: str, colour: str) -> dict[str, Any]:
    """The marker keywords of a point of verdict ``kind`` (one of :data:`VERDICT_KINDS`) in a
    series drawn in ``colour``: the regime figure's and ``biafc compare``'s far-end peaks."""
    if kind == "converted":
        return {"color": colour}
    edge = colour if kind == "undetermined" else "grey"
    return {"color": edge, "mfc": "none", "mec": edge}


def plot_by_verdict(
    ax: Axes,
    x: NDArray[Any],
    y: NDArray[Any],
    verdicts: Sequence[str] | NDArray[Any],
    marker: str,
    colour: str,
    labels: dict[str, str],
    **kwargs: Any,
) -> None:
    """Points ``(x, y)`` styled by their ``verdicts`` (:func:`verdict_marker`), one artist per
    kind present, labelled ``labels[kind]``; NaN ``y`` are left out."""
    kinds = np.array([verdict_kind(str(v)) for v in verdicts], dtype=object)
    finite = np.isfinite(np.asarray(y, dtype=np.float64))
    for kind in VERDICT_KINDS:
        sel = finite & (kinds == kind)
        if sel.any():
            ax.plot(x[sel], y[sel], marker, ls="none", label=labels[kind],
                    **verdict_marker(kind, colour), **kwargs)  # fmt: skip


def on_every_cylinder(
    cylinders: Sequence[int] | NDArray[Any], rows: NDArray[Any]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Rows ``[C, ...]`` of the scanned ``cylinders [C]`` placed on every cylinder from the
    first scanned to the last (``[M, ...]``, NaN where a cylinder was not scanned, so the gap
    background shows), with unit-wide cell edges ``[M + 1]`` at ``cylinder +- 0.5``. Edges at
    midpoints between scanned cylinders stretched cylinder 8's spectrum over cylinders 5-12 of
    a scan of 1, 8 and 16."""
    c = np.asarray(cylinders, dtype=np.int64)
    lo, hi = int(c.min()), int(c.max())
    full = np.full((hi - lo + 1, *rows.shape[1:]), np.nan)
    full[c - lo] = rows
    return np.arange(lo, hi + 2, dtype=np.float64) - 0.5, full


def cell_edges(centres: Sequence[float] | NDArray[Any], log: bool = False) -> NDArray[np.float64]:
    """Cell edges ``[n + 1]`` around ``centres [n]`` (geometric midpoints when ``log``)."""
    c = np.asarray(centres, dtype=np.float64)
    if c.size == 1:
        return np.array([c[0] * 0.9, c[0] * 1.1]) if log else np.array([c[0] - 0.5, c[0] + 0.5])
    if log:
        lc = np.log(c)
        mid = 0.5 * (lc[1:] + lc[:-1])
        return np.exp(np.concatenate([[2 * lc[0] - mid[0]], mid, [2 * lc[-1] - mid[-1]]]))
    mid = 0.5 * (c[1:] + c[:-1])
    return np.concatenate([[2 * c[0] - mid[0]], mid, [2 * c[-1] - mid[-1]]])
