"""The linear limit is drawn white on the dark maps; its legend sample sat on the legend's light
frame, white on white, and could not be seen. The line now carries a dark edge
(:data:`analysis.plots.style.DARK_EDGE`), and so does its legend sample."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from analysis.plots.spatial_plot import plot_spatial_frequency
from analysis.plots.spatiotemporal_plot import plot_spatiotemporal
from analysis.spatial import SpatialFrequencyMap
from analysis.spatiotemporal import SpatiotemporalMap


def _legend_sample(fig: Figure, label: str) -> Line2D:
    for ax in fig.axes:
        legend = ax.get_legend()
        if legend is None:
            continue
        for handle, text in zip(legend.legend_handles, legend.get_texts(), strict=False):
            if text.get_text().startswith(label) and isinstance(handle, Line2D):
                return handle
    raise AssertionError(f"no legend entry {label!r}")


def _edged(line: Line2D) -> bool:
    return line.get_color() in ("white", "w") and bool(line.get_path_effects())


def test_the_linear_limit_is_visible_in_the_legend_of_both_maps() -> None:
    cyl = np.arange(1, 32, dtype=np.int32)
    f = np.linspace(4e3, 13e3, 200)
    onset = np.linspace(8.1e3, 5.5e3, 31)
    cutoff = np.linspace(10.2e3, 8.0e3, 31)
    smap = SpatialFrequencyMap(cyl, f, np.ones((31, 200)), np.full(31, 8e3))
    fig = plot_spatial_frequency(smap, "ltr", 8.92e3, onset, cutoff, far=31)
    assert _edged(_legend_sample(fig, "linear limit"))
    t = np.linspace(0, 0.02, 100)
    st = SpatiotemporalMap(cyl, t, np.ones((31, 100)))
    fig = plot_spatiotemporal([("LTR", st)], linear_limit=17)
    assert _edged(_legend_sample(fig, "linear limit"))
