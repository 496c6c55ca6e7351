"""Matplotlib figures (Agg, no GUI) drawn from the computations in :mod:`analysis`.

Each module draws one kind of figure and returns a ``matplotlib.figure.Figure``;
:func:`analysis.plots.style.save_figure` writes it as PNG and PDF.
"""
