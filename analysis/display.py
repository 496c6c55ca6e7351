"""Readable amplitudes for labels and tables (SI prefixes), shared by text and figures."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["amplitude_label", "amplitude_scale"]


_PREFIXES = ((1.0, ""), (1e-3, "m"), (1e-6, "µ"), (1e-9, "n"))


def amplitude_scale(values: Sequence[float] | NDArray[Any], units: str) -> tuple[float, str]:
    """``(factor, unit)`` to show amplitudes in ``units`` readably: ``values / factor`` in
    ``unit`` (an SI prefix picked for the largest value, e.g. m -> µm for 2e-6)."""
    v = np.abs(np.asarray(values, dtype=np.float64))
    top = float(np.nanmax(v)) if v.size and np.any(np.isfinite(v)) else 1.0
    if units not in ("m", "N", "V", "m/s") or top <= 0:
        return 1.0, units
    for factor, prefix in _PREFIXES:
        if top >= factor:
            return factor, prefix + units
    return _PREFIXES[-1][0], _PREFIXES[-1][1] + units


def amplitude_label(value: float, units: str) -> str:
    """One amplitude as text with a readable prefix, e.g. ``2e-6, "m"`` -> ``"2 µm"``."""
    factor, unit = amplitude_scale([value], units)
    return f"{value / factor:.3g} {unit}"
