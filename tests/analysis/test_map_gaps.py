"""Maps of a scan that skips cylinders: the cylinders not scanned are gaps, never a neighbour's
data stretched over them (a second reader's ``biafc figures`` of the smoke scan: 1, 8, 16)."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np

from analysis.plots.spatial_plot import plot_spatial_frequency
from analysis.plots.spatiotemporal_plot import plot_spatiotemporal
from analysis.plots.style import on_every_cylinder
from analysis.spatial import SpatialFrequencyMap
from analysis.spatiotemporal import SpatiotemporalMap

CYL = np.array([1, 8, 16], dtype=np.int32)


def test_rows_go_to_their_own_cylinder_and_the_rest_are_nan() -> None:
    edges, full = on_every_cylinder(CYL, np.array([[1.0, 1.0], [8.0, 8.0], [16.0, 16.0]]))
    assert np.array_equal(edges, np.arange(1, 18) - 0.5)  # unit-wide cells, 1..16
    assert full.shape == (16, 2)
    assert np.array_equal(full[[0, 7, 15], 0], [1.0, 8.0, 16.0])
    assert np.isnan(np.delete(full, [0, 7, 15], axis=0)).all()


def _mesh_columns(fig) -> np.ndarray:  # type: ignore[no-untyped-def]
    """The first colour mesh's values ``[rows, cylinders]`` and its cylinder edges."""
    mesh = fig.axes[0].collections[0]
    x = mesh.get_coordinates()[0, :, 0]
    return x, np.ma.filled(mesh.get_array(), np.nan).reshape(-1, x.size - 1)


def test_the_spatial_and_spatiotemporal_maps_leave_unscanned_cylinders_empty() -> None:
    f = np.linspace(4e3, 13e3, 50)
    mag = np.vstack([np.exp(-(((f - 9e3) / 1e3) ** 2)) * (i + 1) for i in range(3)])
    smap = SpatialFrequencyMap(CYL, f, mag, np.full(3, 9e3))
    onset, cutoff = np.linspace(8e3, 6e3, 31), np.linspace(10e3, 8e3, 31)
    fig = plot_spatial_frequency(smap, "ltr", 8920.0, onset, cutoff, far=31)
    x, vals = _mesh_columns(fig)
    assert x[0] == 0.5 and x[-1] == 16.5  # was 0.5 .. 20 (edges at midpoints)
    scanned = np.isfinite(vals).any(axis=0)
    assert np.array_equal(np.nonzero(scanned)[0] + 1, CYL)
    assert fig.axes[0].get_xlim() == (0.5, 31.5)
    plt.close(fig)
    t = np.linspace(0.0, 0.01, 40)
    st = SpatiotemporalMap(CYL, t, np.ones((3, t.size)))
    fig = plot_spatiotemporal([("LTR 3 um", st)], 17, n_cylinders=31)
    x, vals = _mesh_columns(fig)
    assert np.array_equal(np.nonzero(np.isfinite(vals).any(axis=0))[0] + 1, CYL)
    assert fig.axes[0].get_xlim() == (0.5, 31.5)  # was -2.5 .. 20: a cylinder 0, no 21-31
    labels = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert "failed or not measured" in labels, labels
    plt.close(fig)
