"""Quantities with units at the edges, SI floats inside.

Every number that a person types (YAML, command line, GUI) carries its unit: ``"8.92 kHz"``,
``"2 um"``, ``"5 N"``, ``"30 ms"``. :func:`parse_quantity` turns such a string into a float in
the SI unit of its dimension and refuses a bare number, an unknown unit or a unit of the wrong
dimension with a one-line :class:`UnitError`.

The pydantic annotated types at the bottom (``Frequency``, ``Length``, ...) make a model field
accept only such strings and store the SI float, so a schema reads ``f_center: Frequency``.
"""

from __future__ import annotations

import math
import re
from typing import Annotated, Any

from pydantic import BeforeValidator, PlainSerializer

__all__ = [
    "DIMENSIONS",
    "Acceleration",
    "Angle",
    "Density",
    "Displacement",
    "Duration",
    "Force",
    "Frequency",
    "Length",
    "Pressure",
    "SampleRate",
    "UnitError",
    "Velocity",
    "Voltage",
    "format_quantity",
    "parse_quantity",
]


class UnitError(ValueError):
    """A quantity without a unit, with an unknown unit, or with a unit of the wrong dimension."""


_PREFIX: dict[str, float] = {
    "p": 1e-12,
    "n": 1e-9,
    "u": 1e-6,
    "µ": 1e-6,
    "μ": 1e-6,
    "m": 1e-3,
    "c": 1e-2,
    "": 1.0,
    "k": 1e3,
    "M": 1e6,
    "G": 1e9,
}

#: dimension name -> {base unit symbol: factor to SI}; prefixes apply to every symbol listed.
DIMENSIONS: dict[str, dict[str, float]] = {
    "frequency": {"Hz": 1.0},
    "sample_rate": {"S/s": 1.0, "Sa/s": 1.0, "Hz": 1.0},
    "length": {"m": 1.0, "in": 0.0254},
    "time": {"s": 1.0, "min": 60.0, "h": 3600.0},
    "force": {"N": 1.0},
    "voltage": {"V": 1.0, "Vpp": 1.0},
    "velocity": {"m/s": 1.0},
    "acceleration": {"m/s^2": 1.0, "m/s2": 1.0},
    "pressure": {"Pa": 1.0},
    "density": {"kg/m^3": 1.0, "kg/m3": 1.0, "g/cm^3": 1000.0, "g/cm3": 1000.0},
    "angle": {"deg": math.pi / 180.0, "rad": 1.0},
    "dimensionless": {"": 1.0},
}

#: the SI unit written back by :func:`format_quantity`
SI_SYMBOL: dict[str, str] = {
    "frequency": "Hz",
    "sample_rate": "S/s",
    "length": "m",
    "time": "s",
    "force": "N",
    "voltage": "V",
    "velocity": "m/s",
    "acceleration": "m/s^2",
    "pressure": "Pa",
    "density": "kg/m^3",
    "angle": "rad",
    "dimensionless": "",
}

_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_QUANTITY_RE = re.compile(rf"^\s*({_NUMBER})\s*(.*?)\s*$")
# prefixes that are never applied to these (to keep "min", "in", "m/s" unambiguous)
_NO_PREFIX = {"min", "h", "in", "deg", "rad"}


def _unit_factor(unit: str, dimension: str) -> float | None:
    table = DIMENSIONS[dimension]
    if unit in table:
        return table[unit]
    for symbol, factor in table.items():
        if not symbol or symbol in _NO_PREFIX or not unit.endswith(symbol):
            continue
        prefix = unit[: len(unit) - len(symbol)]
        if prefix in _PREFIX and prefix != "":
            return _PREFIX[prefix] * factor
    return None


def parse_quantity(value: Any, dimension: str, *, field: str = "") -> float:
    """Parse ``"<number> <unit>"`` into a float in the SI unit of ``dimension``.

    Parameters
    ----------
    value:
        A string such as ``"8.92 kHz"``; for ``dimension="dimensionless"`` a plain number too.
    dimension:
        A key of :data:`DIMENSIONS` (``"frequency"``, ``"length"``, ...).
    field:
        Name used in the error message.

    Raises
    ------
    UnitError
        For a bare number (other than dimensionless), an unknown unit, a unit of another
        dimension, or a non-finite value.
    """
    if dimension not in DIMENSIONS:
        raise UnitError(f"unknown dimension {dimension!r}")
    where = f"{field}: " if field else ""
    expected = "/".join(k for k in DIMENSIONS[dimension] if k) or "no unit"
    if isinstance(value, bool):
        raise UnitError(f"{where}expected a {dimension} with a unit ({expected}), got {value!r}")
    if isinstance(value, int | float):
        if dimension == "dimensionless":
            number = float(value)
            if not math.isfinite(number):
                raise UnitError(f"{where}value must be finite, got {value!r}")
            return number
        example = f"{value} {expected.split('/')[0]}"
        raise UnitError(f"{where}{value!r} has no unit; write it with one, e.g. '{example}'")
    if not isinstance(value, str):
        raise UnitError(f"{where}expected a quantity string such as '8.92 kHz', got {value!r}")
    match = _QUANTITY_RE.match(value)
    if not match:
        raise UnitError(f"{where}cannot read {value!r} as '<number> <unit>'")
    number = float(match.group(1))
    unit = match.group(2)
    if not math.isfinite(number):
        raise UnitError(f"{where}value must be finite, got {value!r}")
    if unit == "" and dimension != "dimensionless":
        example = f"{number:g} {expected.split('/')[0]}"
        raise UnitError(f"{where}{value!r} has no unit; write it with one, e.g. '{example}'")
    factor = _unit_factor(unit, dimension)
    if factor is None:
        raise UnitError(f"{where}unit {unit!r} is not a {dimension} unit (use {expected})")
    return number * factor


def format_quantity(value_si: float, dimension: str, *, digits: int = 4) -> str:
    """Format an SI value with an engineering prefix, e.g. ``8920.0 -> '8.92 kHz'``."""
    symbol = SI_SYMBOL[dimension]
    if dimension in ("dimensionless", "angle", "density", "acceleration") or value_si == 0:
        return f"{value_si:.{digits}g} {symbol}".strip()
    exponent = int(math.floor(math.log10(abs(value_si)) / 3) * 3)
    exponent = max(-12, min(9, exponent))
    prefixes = {-12: "p", -9: "n", -6: "u", -3: "m", 0: "", 3: "k", 6: "M", 9: "G"}
    return f"{value_si / 10**exponent:.{digits}g} {prefixes[exponent]}{symbol}"


def _validator(dimension: str) -> BeforeValidator:
    def check(value: Any) -> float:
        return parse_quantity(value, dimension)

    return BeforeValidator(check)


def _serializer(dimension: str) -> PlainSerializer:
    return PlainSerializer(lambda v: format_quantity(v, dimension, digits=12), return_type=str)


Frequency = Annotated[float, _validator("frequency"), _serializer("frequency")]
SampleRate = Annotated[float, _validator("sample_rate"), _serializer("sample_rate")]
Length = Annotated[float, _validator("length"), _serializer("length")]
Displacement = Length
Duration = Annotated[float, _validator("time"), _serializer("time")]
Force = Annotated[float, _validator("force"), _serializer("force")]
Voltage = Annotated[float, _validator("voltage"), _serializer("voltage")]
Velocity = Annotated[float, _validator("velocity"), _serializer("velocity")]
Acceleration = Annotated[float, _validator("acceleration"), _serializer("acceleration")]
Pressure = Annotated[float, _validator("pressure"), _serializer("pressure")]
Density = Annotated[float, _validator("density"), _serializer("density")]
Angle = Annotated[float, _validator("angle"), _serializer("angle")]
