"""Quantities with units at the edges, SI floats inside: one pint registry for the project.

Every number that a person types (YAML, command line, GUI) carries its unit: ``"8.92 kHz"``,
``"2 um"`` (or ``"2 µm"``, ``"2 micron"``), ``"5 N"``, ``"30 ms"``, ``"50 mm/s/V"``,
``"0.05 um/V"``, ``"2 Vpp"``. :func:`parse_quantity` reads such a string with :mod:`pint` and
returns a float in the unit of the named dimension (:data:`DIMENSIONS`: SI, or Vpp for a
peak-to-peak voltage); it refuses a bare number, an unknown unit or a unit of the wrong
dimension with a one-line :class:`UnitError` that names what was given and what is expected
(``'2 um' is a length, expected a frequency (Hz, kHz)``).

The registry holds the units of this project only, defined once in :data:`DEFINITIONS`: the SI
units a bench file or protocol uses with their prefixes, a few others a lab types (micron,
inch, min, h, deg), ``Vpp``/``Vpk`` (peak-to-peak and peak volts: ``1 Vpk = 2 Vpp``) and the
sample (``S``, ``Sa``: ``1 MS/s``). Compound units (``um/V``, ``mm/s/V``, ``N/V``,
``kg/m^3``) are pint's products of these. Built on first use (a few ms after ``import pint``,
0.15-0.23 s), never at import, and only for a unit this machine has not read before: pint's
answers are remembered in the user cache folder (:mod:`instruments.unit_memo`).

The pydantic annotated types at the bottom (``Frequency``, ``Length``, ...) make a model field
accept only such strings and store the float, so a schema reads ``f_center: Frequency``.
"""

from __future__ import annotations

import importlib.util
import math
import os
import re
import threading
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Annotated, Any

from pydantic import BeforeValidator, PlainSerializer

from instruments.unit_memo import UnitMemo

__all__ = [
    "DEFINITIONS",
    "DIMENSIONS",
    "Acceleration",
    "Angle",
    "Density",
    "Displacement",
    "Duration",
    "Force",
    "ForcePerVolt",
    "Frequency",
    "Length",
    "LengthPerVolt",
    "PeakToPeakVoltage",
    "Pressure",
    "SampleRate",
    "UnitError",
    "Velocity",
    "VelocityPerVolt",
    "Voltage",
    "dimension_of",
    "format_quantity",
    "parse_quantity",
    "registry",
]


class UnitError(ValueError):
    """A quantity without a unit, with an unknown unit, or with a unit of the wrong dimension."""


#: the project's units, in pint's definition syntax: the one place they are defined
DEFINITIONS = """
pico- = 1e-12 = p-
nano- = 1e-9 = n-
micro- = 1e-6 = µ- = μ- = u-
milli- = 1e-3 = m-
centi- = 1e-2 = c-
kilo- = 1e3 = k-
mega- = 1e6 = M-
giga- = 1e9 = G-
meter = [length] = m = metre
second = [time] = s = sec
gram = [mass] = g
volt = [voltage] = V
radian = [] = rad
sample = [] = S = Sa
micron = micrometer
inch = 0.0254 * meter = in
minute = 60 * second = min
hour = 60 * minute = h = hr
degree = 0.017453292519943295 * radian = deg
hertz = 1 / second = Hz
newton = kilogram * meter / second ** 2 = N
pascal = newton / meter ** 2 = Pa
volt_peak = volt = Vpk = V_pk
volt_peak_to_peak = 0.5 * volt = Vpp = V_pp
"""


@dataclass(frozen=True)
class Dimension:
    """A kind of quantity: the unit its floats are in, how to name it, units to suggest."""

    unit: str
    name: str
    examples: str


#: dimension name -> the unit of the float :func:`parse_quantity` returns, its name in messages,
#: and units to suggest
DIMENSIONS: dict[str, Dimension] = {
    "frequency": Dimension("Hz", "a frequency", "Hz, kHz"),
    "sample_rate": Dimension("S/s", "a sample rate", "S/s, kS/s, MS/s"),
    "length": Dimension("m", "a length", "m, mm, um"),
    "time": Dimension("s", "a duration", "s, ms, us"),
    "force": Dimension("N", "a force", "N, mN"),
    "mass": Dimension("kg", "a mass", "kg, g"),
    "voltage": Dimension("V", "a voltage", "V, mV"),
    "peak_to_peak_voltage": Dimension("Vpp", "a peak-to-peak voltage", "Vpp, mVpp, Vpk"),
    "velocity": Dimension("m/s", "a velocity", "m/s, mm/s"),
    "acceleration": Dimension("m/s^2", "an acceleration", "m/s^2"),
    "pressure": Dimension("Pa", "a pressure", "Pa, GPa"),
    "density": Dimension("kg/m^3", "a density", "kg/m^3, g/cm^3"),
    "length_per_volt": Dimension("m/V", "a length per volt", "um/V, nm/V"),
    "velocity_per_volt": Dimension("m/s/V", "a velocity per volt", "mm/s/V"),
    "force_per_volt": Dimension("N/V", "a force per volt", "N/V"),
    "angle": Dimension("rad", "an angle", "deg, rad"),
    "dimensionless": Dimension("", "a plain number", "no unit"),
}

#: a bare volt (with a prefix): it does not say whether it is a peak or a peak-to-peak value
_BARE_VOLT = re.compile(r"^[pnuµμmckMG]?V$")

_LOCK = threading.Lock()


@lru_cache(maxsize=1)
def _build_registry() -> Any:
    import sys

    # pint imports dask (and xarray) when installed, for array support this project does not
    # use: 0.1 s more at the first quantity, and thousands of objects that lengthened the
    # window's garbage collections during a run. Hidden while pint is imported, then restored.
    hidden = [m for m in ("dask", "xarray") if m not in sys.modules]
    for m in hidden:
        sys.modules[m] = None  # type: ignore[assignment]
    try:
        import pint
    finally:
        for m in hidden:
            if m in sys.modules and sys.modules[m] is None:
                del sys.modules[m]

    ureg: Any = pint.UnitRegistry(None, autoconvert_offset_to_baseunit=False)
    for line in DEFINITIONS.strip().splitlines():
        ureg.define(line)
    return ureg


def registry() -> Any:
    """The project's :class:`pint.UnitRegistry` (built on first use, then shared)."""
    with _LOCK:
        return _build_registry()


_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_QUANTITY_RE = re.compile(rf"^\s*({_NUMBER})\s*(.*?)\s*$", re.DOTALL)
#: what a unit may be written with (pint would also evaluate arithmetic: never given that)
_UNIT_CHARS = re.compile(r"^[A-Za-zµμ_/*^().·²³\s0-9+-]{0,40}$")
#: "cm3", "s2": a power written without its operator
_BARE_POWER = re.compile(r"(?<=[A-Za-zµμ])([23])(?![0-9A-Za-z])")
_EXPONENT = re.compile(r"(?:\^|\*\*)\s*\(?\s*[-+]?\d{1,2}\s*\)?")
_TOWER = re.compile(r"\*\*[\s()+-]*\d+[\s()]*\*\*")


def _unit_text(unit: str) -> str | None:
    """``unit`` as pint reads it (``^`` and bare powers as ``**``), or ``None`` when it is not
    a product of unit names with small integer powers."""
    if not _UNIT_CHARS.match(unit):
        return None
    text = unit.replace("·", "*").replace("²", "2").replace("³", "3")
    text = _BARE_POWER.sub(r"**\1", text).replace("^", "**")
    if _TOWER.search(text):  # a power of a power: pint would compute it, however large
        return None
    rest = _EXPONENT.sub(" ", text)
    if re.search(r"\d", rest) or "**" in rest:  # a number that is not a small power
        return None
    return text


@lru_cache(maxsize=1)
def _memo() -> UnitMemo:
    """The answers pint gave on this machine (:mod:`instruments.unit_memo`), keyed by this
    module's source and the installed pint (found, not imported)."""
    from instruments.user_cache import cache_dir

    spec = importlib.util.find_spec("pint")
    origin = spec.origin if spec is not None and spec.origin else ""
    stat = os.stat(origin) if origin else None
    pint_id = f"{origin} {stat.st_size} {stat.st_mtime_ns}" if stat is not None else "no pint"
    return UnitMemo(cache_dir(), [Path(__file__).read_bytes(), pint_id])


@lru_cache(maxsize=512)
def _factor(unit: str, dimension: str) -> tuple[float | None, str]:
    """(factor from ``unit`` to the dimension's unit, or ``None``; what ``unit`` is): as pint
    answered on this machine before (:func:`_memo`), else :func:`_pint_factor`."""
    if "\0" in unit:  # the memo's separator; never a unit anyway
        return _pint_factor(unit, dimension)
    memo = _memo()
    answer = memo.recall(unit, dimension)
    if answer is None:
        answer = _pint_factor(unit, dimension)
        memo.remember(unit, dimension, answer)
    return answer


def _pint_factor(unit: str, dimension: str) -> tuple[float | None, str]:
    """:func:`_factor`, by pint."""
    ureg = registry()
    import pint  # imported by registry()

    text = _unit_text(unit)
    if text is None:
        return None, "unreadable"
    try:
        units = ureg.parse_units(text)
    except pint.UndefinedUnitError as exc:
        names = getattr(exc, "unit_names", None) or ()
        shown = ", ".join(repr(n) for n in ([names] if isinstance(names, str) else names))
        return None, f"unknown unit {shown or repr(unit)}"
    except Exception:
        return None, "unreadable"
    target = ureg.parse_units(_unit_text(DIMENSIONS[dimension].unit) or "")
    if units.dimensionality != target.dimensionality:
        return None, _dimension_name(units)
    return float(ureg.Quantity(1.0, units).to(target).magnitude), ""


def _dimension_name(units: Any) -> str:
    """``'is a length'`` for a unit of a known dimension, else ``'has unit m * s'``."""
    if units.dimensionless:
        return "has no dimension"
    ureg = registry()
    for dim in DIMENSIONS.values():
        if dim.unit and ureg.parse_units(_unit_text(dim.unit) or "").dimensionality == (
            units.dimensionality
        ):
            return f"is {dim.name}"
    return f"has unit {units:~}"


def dimension_of(value: Any) -> str | None:
    """The first key of :data:`DIMENSIONS` whose unit ``value`` (``"<number> <unit>"``) is
    written in (``"2 Vpp"`` -> ``"voltage"``, ``"2 um"`` -> ``"length"``), or ``None`` (no
    unit, an unknown or unreadable one, or a string that is no quantity)."""
    if not isinstance(value, str):
        return None
    match = _QUANTITY_RE.match(value)
    if not match or not match.group(2):
        return None
    for name in DIMENSIONS:
        if name != "dimensionless" and _factor(match.group(2), name)[0] is not None:
            return name
    return None


def parse_quantity(value: Any, dimension: str, *, field: str = "") -> float:
    """Parse ``"<number> <unit>"`` into a float in the unit of ``dimension``.

    Parameters
    ----------
    value:
        A string such as ``"8.92 kHz"``, ``"8.92kHz"``, ``"2 µm"``, ``"50 mm/s/V"``; for
        ``dimension="dimensionless"`` a plain number too.
    dimension:
        A key of :data:`DIMENSIONS` (``"frequency"``, ``"length"``, ...).
    field:
        Name used in the error message.

    Raises
    ------
    UnitError
        One line, for a bare number (other than dimensionless), an unknown unit, a unit of
        another dimension (``'2 um' is a length, expected a frequency (Hz, kHz)``), a bare
        volt where a peak-to-peak voltage is asked for, or a non-finite value.
    """
    if dimension not in DIMENSIONS:
        raise UnitError(f"unknown dimension {dimension!r}")
    dim = DIMENSIONS[dimension]
    where = f"{field}: " if field else ""
    expected = f"expected {dim.name} ({dim.examples})"
    first = dim.examples.split(",")[0]
    if isinstance(value, bool):
        raise UnitError(f"{where}{value!r} is not a quantity; {expected}")
    if isinstance(value, int | float):
        if dimension == "dimensionless":
            number = float(value)
            if not math.isfinite(number):
                raise UnitError(f"{where}value must be finite, got {value!r}")
            return number
        raise UnitError(f"{where}{value!r} has no unit; write it with one, e.g. '{value} {first}'")
    if not isinstance(value, str):
        raise UnitError(f"{where}expected a quantity string such as '8.92 kHz', got {value!r}")
    match = _QUANTITY_RE.match(value)
    if not match:
        raise UnitError(f"{where}cannot read {value!r} as '<number> <unit>'; {expected}")
    number = float(match.group(1))
    unit = match.group(2)
    if not math.isfinite(number):
        raise UnitError(f"{where}value must be finite, got {value!r}")
    if unit == "" and dimension != "dimensionless":
        raise UnitError(
            f"{where}{value!r} has no unit; write it with one, e.g. '{number:g} {first}'"
        )
    if dimension == "peak_to_peak_voltage" and _BARE_VOLT.match(unit):
        raise UnitError(
            f"{where}{value!r} does not say peak or peak-to-peak; write '{number:g} {unit}pp' "
            f"or '{number:g} {unit}pk'"
        )
    factor, what = _factor(unit, dimension)
    if factor is None:
        if what == "unreadable":
            raise UnitError(f"{where}cannot read the unit of {value!r}; {expected}")
        if what.startswith("unknown unit"):
            raise UnitError(f"{where}{what} in {value!r}; {expected}")
        raise UnitError(f"{where}{value!r} {what}, {expected}")
    result = number * factor
    if not math.isfinite(result):
        raise UnitError(f"{where}value must be finite, got {value!r}")
    return result


def format_quantity(value: float, dimension: str, *, digits: int = 4) -> str:
    """Format a float in the unit of ``dimension`` with an engineering prefix, e.g.
    ``8920.0 -> '8.92 kHz'``; :func:`parse_quantity` reads it back."""
    symbol = DIMENSIONS[dimension].unit
    plain = ("dimensionless", "angle", "density", "acceleration", "mass")
    if dimension in plain or value == 0 or not math.isfinite(value):
        return f"{value:.{digits}g} {symbol}".strip()
    exponent = int(math.floor(math.log10(abs(value)) / 3) * 3)
    exponent = max(-12, min(9, exponent))
    prefixes = {-12: "p", -9: "n", -6: "u", -3: "m", 0: "", 3: "k", 6: "M", 9: "G"}
    return f"{value / 10**exponent:.{digits}g} {prefixes[exponent]}{symbol}"


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
PeakToPeakVoltage = Annotated[
    float, _validator("peak_to_peak_voltage"), _serializer("peak_to_peak_voltage")
]
Velocity = Annotated[float, _validator("velocity"), _serializer("velocity")]
Acceleration = Annotated[float, _validator("acceleration"), _serializer("acceleration")]
Pressure = Annotated[float, _validator("pressure"), _serializer("pressure")]
Density = Annotated[float, _validator("density"), _serializer("density")]
Angle = Annotated[float, _validator("angle"), _serializer("angle")]
LengthPerVolt = Annotated[float, _validator("length_per_volt"), _serializer("length_per_volt")]
VelocityPerVolt = Annotated[
    float, _validator("velocity_per_volt"), _serializer("velocity_per_volt")
]
ForcePerVolt = Annotated[float, _validator("force_per_volt"), _serializer("force_per_volt")]
