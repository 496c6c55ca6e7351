"""The protocol file schema: what to measure, in which order, with units on every number.

A protocol file (YAML) looks like::

    name: ltr_highamp
    directions: [ltr]                 # ltr, rtl or both
    burst:
      ltr: {f_center: 8.92 kHz, shape: narrowband}   # or cycles: 21, width: 0.39 ms (sigma
      rtl: {f_center: 6.63 kHz, sigma_f: 0.3 kHz}     # in time), sigma_f (sigma in frequency)
    amplitudes: [2 Vpp, 5 Vpp]        # generator volts peak-to-peak (Vpp) or peak (Vpk; a bare
                                      # V is refused), or peak actuator displacement (um, m); or
                                      # {start: 0.1 Vpp, stop: 10 Vpp, count: 6, spacing: log}
    cylinders: all                    # or [1, 5, 16, 31]
    averages: 4
    acquisition: {rate: 1 MS/s, duration: 20 ms, pre_trigger: 1 ms}
    settle: 50 ms
    order: [direction, amplitude, cylinder]   # outermost loop first
    output: "runs/{name}_{timestamp}.h5"
    on_point_failure: continue        # or stop
    retries: 2
    max_failed_in_a_row: 10           # the run ends failed after this many failed points in a
                                      # row: the bench needs attention (0: never)

Load with :func:`load_protocol`; every error is one line ``FILE:LINE: field: message``. Every
number is bounded (:data:`BOUNDS`: durations, rates, cycles; counts and cylinders by their
validators); the checks against a bench (limits, Nyquist, the record, memory) are in
:func:`daq.engine.make_plan`, run through :func:`daq.request.validate_request`.
"""

from __future__ import annotations

import math
import re
import string
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from instruments.units import (
    Duration,
    Frequency,
    SampleRate,
    UnitError,
    format_quantity,
    parse_quantity,
)
from protocols.yamlfile import ConfigError, YamlDoc, load_yaml, parse_yaml, validate

__all__ = [
    "BOUNDS",
    "AcquisitionSpec",
    "AmplitudeRange",
    "BurstSpec",
    "Protocol",
    "ProtocolFile",
    "amplitude_notation",
    "load_protocol",
    "parse_protocol",
    "resolve_protocol_path",
    "shipped_protocols",
]

Direction = Literal["ltr", "rtl"]
AmplitudeKind = Literal["generator_Vpp", "displacement_m"]
LoopName = Literal["direction", "amplitude", "cylinder"]


_DEFAULT_ORDER: tuple[LoopName, ...] = ("direction", "amplitude", "cylinder")


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


#: a generator amplitude: number, optional prefix, V, then pp (peak-to-peak) or pk (peak)
_VOLTS = re.compile(
    r"^\s*(?P<number>[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(?P<prefix>[pnuµμmk]?)V"
    r"\s*(?P<kind>pp|p-p|pk|peak)?\s*$"
)


def amplitude_notation(value: Any) -> Literal["Vpp", "Vpk", "m"]:
    """How an amplitude was written: generator volts peak-to-peak (``"2 Vpp"``), peak
    (``"1 Vpk"``, ``"1 V peak"``), or a peak actuator displacement (``"1.5 um"``)."""
    m = _VOLTS.match(value) if isinstance(value, str) else None
    if m is None:
        return "m"
    return "Vpp" if m.group("kind") in ("pp", "p-p") else "Vpk"


def parse_amplitude(value: Any) -> tuple[AmplitudeKind, float]:
    """``"2 Vpp"`` -> ``("generator_Vpp", 2.0)``; ``"1 Vpk"`` (or ``"1 V peak"``) ->
    ``("generator_Vpp", 2.0)``; ``"1.5 um"`` (peak displacement) -> ``("displacement_m",
    1.5e-6)``. A bare ``"1 V"`` is refused: it says neither peak nor peak-to-peak."""
    kind: AmplitudeKind
    m = _VOLTS.match(value) if isinstance(value, str) else None
    if m is not None:
        if m.group("kind") is None:
            n = m.group("number") + " " + m.group("prefix")
            raise UnitError(
                f"amplitude {value!r}: say peak-to-peak ({n}Vpp) or peak ({n}Vpk); "
                "a bare V is ambiguous"
            )
        volts = parse_quantity(f"{m.group('number')} {m.group('prefix')}V", "voltage")
        v, kind = volts * (1.0 if m.group("kind") in ("pp", "p-p") else 2.0), "generator_Vpp"
    else:
        try:
            v, kind = parse_quantity(value, "length"), "displacement_m"
        except UnitError:
            raise UnitError(
                f"amplitude {value!r}: write generator volts peak-to-peak ('2 Vpp') or peak "
                "('1 Vpk'), or a peak actuator displacement ('1.5 um')"
            ) from None
    if not (math.isfinite(v) and v > 0):
        raise UnitError(f"amplitude must be > 0, got {value!r}")
    return kind, v


#: bounds of the protocol's numbers: (low, high) in SI; a value outside is refused
BOUNDS: dict[str, tuple[float, float]] = {
    "f_center": (1.0, 10e6),  # Hz
    "cycles": (1.0, 1000.0),
    "width": (1e-7, 1.0),  # s
    "rate": (1e3, 100e6),  # S/s
    "duration": (1e-5, 10.0),  # s, one record
    "pre_trigger": (0.0, 1.0),  # s
    "timeout": (10e-3, 3600.0),  # s, one read
    "settle": (0.0, 600.0),  # s, after each move
}


def outside_bounds(field: str, value: float, dimension: str | None) -> str | None:
    """Why ``value`` is outside :data:`BOUNDS` ``[field]``, naming the value and the range
    (``"100 s is outside 10 us .. 10 s"``), or None; the protocol's check and the model
    commands' (``daq/cli/simulate_request.py``) both say it so."""
    lo, hi = BOUNDS[field]
    if math.isfinite(value) and lo <= value <= hi:
        return None

    def show(x: float) -> str:
        if dimension == "time" and x >= 1000:
            return f"{x:.4g} s"
        return format_quantity(x, dimension) if dimension else f"{x:g}"

    return (
        f"{show(value)} is outside {show(lo)} .. {show(hi)}"
        if math.isfinite(value)
        else f"{value!r} is not a finite number; give {show(lo)} .. {show(hi)}"
    )


def _within(field: str, value: float, dimension: str | None, named: bool = True) -> None:
    """Refuse :func:`outside_bounds` (naming the field, for a model-level check: ``named``)."""
    why = outside_bounds(field, value, dimension)
    if why is not None:
        raise ValueError(f"{field}: {why}" if named else why)


def _whole(field: str, v: Any, low: int, high: int) -> int:
    """A whole number ``low .. high`` (not a boolean, not a float) or a one-line refusal."""
    if isinstance(v, bool) or not isinstance(v, int) or not low <= v <= high:
        shown = ("true" if v else "false") if isinstance(v, bool) else repr(v)
        raise ValueError(f"{shown}: give a whole number from {low} to {high}")
    return v


def _no_bool(v: Any) -> Any:
    if isinstance(v, bool):
        raise ValueError(f"expected a number, got {'true' if v else 'false'}")
    return v


class BurstSpec(_Model):
    """One direction's burst: centre frequency (Hz) and exactly one width: ``cycles`` in the
    window, ``width`` (Gaussian sigma in time, s), ``sigma_f`` (Gaussian sigma in frequency,
    Hz) or ``shape`` (a name of :data:`instruments.burst.NAMED_BURSTS`: ``narrowband``, the
    default of the shipped protocols, or ``five_cycle``)."""

    f_center: Frequency
    cycles: float | None = None
    width: Duration | None = None
    sigma_f: Frequency | None = None
    shape: str | None = None

    @field_validator("cycles", mode="before")
    @classmethod
    def _cycles_number(cls, v: Any) -> Any:
        return _no_bool(v)

    @model_validator(mode="after")
    def _one_of(self) -> BurstSpec:
        from instruments.burst import NAMED_BURSTS

        given = [self.cycles, self.width, self.sigma_f, self.shape]
        if sum(x is not None for x in given) != 1:
            raise ValueError("give exactly one of 'cycles', 'width', 'sigma_f' or 'shape'")
        _within("f_center", self.f_center, "frequency")
        if self.cycles is not None:
            _within("cycles", self.cycles, None)
        if self.width is not None:
            _within("width", self.width, "time")
        if self.sigma_f is not None and not 0 < self.sigma_f < self.f_center:
            raise ValueError(
                f"sigma_f: {format_quantity(self.sigma_f, 'frequency')} must be > 0 and below "
                f"f_center ({format_quantity(self.f_center, 'frequency')})"
            )
        if self.shape is not None and self.shape not in NAMED_BURSTS:
            raise ValueError(f"shape: one of {', '.join(NAMED_BURSTS)}, got {self.shape!r}")
        return self

    def burst(self) -> Any:
        """The :class:`instruments.burst.Burst` of this spec."""
        from instruments.burst import NAMED_BURSTS, Burst, width_from_sigma_f

        if self.width is not None:
            return Burst(self.f_center, cycles=None, width_s=self.width)
        if self.sigma_f is not None:
            return Burst(self.f_center, cycles=None, width_s=width_from_sigma_f(self.sigma_f))
        if self.shape is not None:
            return Burst(self.f_center, cycles=NAMED_BURSTS[self.shape])
        return Burst(self.f_center, cycles=self.cycles)


class AmplitudeRange(_Model):
    """``count`` amplitudes from ``start`` to ``stop`` (both with units), linear or log spaced."""

    start: str
    stop: str
    count: int

    @field_validator("count", mode="before")
    @classmethod
    def _count(cls, v: Any) -> int:
        return _whole("count", v, 1, 10_000)

    spacing: Literal["linear", "log"] = "linear"

    @field_validator("start", "stop", mode="before")
    @classmethod
    def _quantity(cls, v: Any) -> str:
        parse_amplitude(v)
        return str(v)


class AcquisitionSpec(_Model):
    """Digitiser record: rate (S/s), duration after the trigger (s), pre-trigger (s)."""

    rate: SampleRate
    duration: Duration
    pre_trigger: Duration = 0.0
    timeout: Duration = 10.0

    @model_validator(mode="after")
    def _bounded(self) -> AcquisitionSpec:
        _within("rate", self.rate, "sample_rate")
        _within("duration", self.duration, "time")
        _within("pre_trigger", self.pre_trigger, "time")
        _within("timeout", self.timeout, "time")
        record = self.pre_trigger + self.duration
        if self.timeout <= record:
            raise ValueError(
                f"timeout: {format_quantity(self.timeout, 'time')} is not longer than the "
                f"record ({format_quantity(record, 'time')} with the pre-trigger): every read "
                "would time out"
            )
        return self

    @property
    def n_pretrigger(self) -> int:
        return round(self.pre_trigger * self.rate)

    def n_samples(self, rate_Hz: float | None = None) -> int:
        """Samples per record at ``rate_Hz`` (default: the requested rate)."""
        r = self.rate if rate_Hz is None else rate_Hz
        return round(self.pre_trigger * r) + round(self.duration * r)


#: a protocol name: it becomes part of the run file's name
_SAFE_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,63}")
#: the fields an output pattern may use
_OUTPUT_FIELDS = frozenset({"name", "timestamp", "date"})


class Protocol(_Model):
    """A validated protocol. Quantities are SI floats; amplitudes via :meth:`amplitude_values`."""

    name: str = Field(min_length=1)
    description: str = ""
    directions: list[Direction] | Literal["both"]
    burst: dict[Direction, BurstSpec]
    amplitudes: list[str] | AmplitudeRange
    cylinders: Literal["all"] | list[int] = "all"
    averages: int = 1
    acquisition: AcquisitionSpec
    settle: Duration = 0.0
    order: list[LoopName] = Field(default_factory=lambda: list(_DEFAULT_ORDER))
    output: str = "runs/{name}_{timestamp}.h5"
    on_point_failure: Literal["continue", "stop"] = "continue"
    retries: int = 2
    #: with ``on_point_failure: continue``: the run ends failed once this many points in a row
    #: failed every attempt (a trigger cable out, the laser spot lost: every point would fail,
    #: each after its retries and timeouts); 0: never
    max_failed_in_a_row: int = 10

    @field_validator("name")
    @classmethod
    def _safe_name(cls, v: str) -> str:
        if not _SAFE_NAME.fullmatch(v):
            raise ValueError(
                f"{v!r}: use letters, digits, '.', '_' and '-' (1 to 64 characters, starting "
                "with a letter or digit); it becomes part of a file name"
            )
        return v

    @field_validator("output")
    @classmethod
    def _known_fields_only(cls, v: str) -> str:
        if any(c in v for c in "\0\n\r"):
            raise ValueError("the output pattern holds a NUL byte or a line break")
        try:
            parts = list(string.Formatter().parse(v))
        except ValueError as exc:
            raise ValueError(
                f"bad pattern ({exc}); use {{name}}, {{timestamp}}, {{date}}"
            ) from None
        for _, field, spec, conversion in parts:
            if field is None:
                continue
            if field not in _OUTPUT_FIELDS or spec or conversion:
                shown = (
                    field + (f"!{conversion}" if conversion else "") + (f":{spec}" if spec else "")
                )
                raise ValueError(
                    f"{{{shown}}} is not allowed in the output pattern; use only {{name}}, "
                    "{timestamp} and {date}, with no attribute, index, conversion or format"
                )
        return v

    @field_validator("amplitudes", mode="before")
    @classmethod
    def _amplitude_list(cls, v: Any) -> Any:
        if isinstance(v, list):
            if not v:
                raise ValueError("give at least one amplitude")
            if len(v) > 10_000:
                raise ValueError(f"{len(v)} amplitudes; at most 10000")
            parsed = [parse_amplitude(a) for a in v]
            kinds = {k for k, _ in parsed}
            if len(kinds) > 1:
                raise ValueError("mix of generator (Vpp) and displacement (m) amplitudes")
            values = np.array([value for _, value in parsed])
            order = np.argsort(values, kind="stable")  # neighbours once sorted: n log n
            ranked = values[order]
            same = np.isclose(ranked[1:], ranked[:-1], rtol=1e-9, atol=0.0)  # '0.5 um', '500 nm'
            if same.any():  # as a cylinder listed twice is refused
                k = int(np.argmax(same))
                j, i = sorted((int(order[k]), int(order[k + 1])))
                raise ValueError(
                    f"amplitude {i + 1} ({v[i]}) is amplitude {j + 1} ({v[j]}) again: "
                    "list each once"
                )
            return [str(a) for a in v]
        return v

    @field_validator("averages", mode="before")
    @classmethod
    def _averages(cls, v: Any) -> int:
        return _whole("averages", v, 1, 10_000)

    @field_validator("retries", mode="before")
    @classmethod
    def _retries(cls, v: Any) -> int:
        return _whole("retries", v, 0, 100)

    @field_validator("max_failed_in_a_row", mode="before")
    @classmethod
    def _max_failed_in_a_row(cls, v: Any) -> int:
        return _whole("max_failed_in_a_row", v, 0, 1_000_000)

    @field_validator("cylinders", mode="before")
    @classmethod
    def _cylinder_list(cls, v: Any) -> Any:
        if v == "all":
            return v
        if not isinstance(v, list):
            raise ValueError(f"'all' or a list of cylinder numbers such as [1, 16, 31], got {v!r}")
        if not v:
            raise ValueError("[] names no cylinder; give 'all' or a list such as [1, 16, 31]")
        if len(v) > 1000:
            raise ValueError(f"{len(v)} cylinders listed; at most 1000")
        for i, c in enumerate(v):
            if isinstance(c, bool) or not isinstance(c, int) or not 1 <= c <= 1000:
                shown = ("true" if c else "false") if isinstance(c, bool) else repr(c)
                raise ValueError(
                    f"entry {i + 1} ({shown}) is not a cylinder number (a whole number from 1)"
                )
        return v

    @field_validator("directions", mode="before")
    @classmethod
    def _directions(cls, v: Any) -> Any:
        if isinstance(v, str) and v in ("ltr", "rtl"):
            return [v]
        return v

    @field_validator("settle")
    @classmethod
    def _settle(cls, v: float) -> float:
        _within("settle", v, "time", named=False)
        return v

    @model_validator(mode="after")
    def _check(self) -> Protocol:
        dirs = self.direction_list
        if len(set(dirs)) != len(dirs) or not dirs:
            raise ValueError("directions: give ltr, rtl or both (each at most once)")
        for d in dirs:
            if d not in self.burst:
                raise ValueError(f"burst: no burst for direction {d!r}")
        if sorted(self.order) != ["amplitude", "cylinder", "direction"]:
            raise ValueError("order: list direction, amplitude and cylinder once each")
        if isinstance(self.cylinders, list) and len(set(self.cylinders)) != len(self.cylinders):
            twice = sorted({c for c in self.cylinders if self.cylinders.count(c) > 1})
            raise ValueError(
                f"cylinders: cylinder {', '.join(str(c) for c in twice)} is listed twice; "
                "list each once"
            )
        if isinstance(self.amplitudes, AmplitudeRange):
            k1, v1 = parse_amplitude(self.amplitudes.start)
            k2, v2 = parse_amplitude(self.amplitudes.stop)
            if k1 != k2:
                raise ValueError("amplitudes: start and stop have different kinds of unit")
            if self.amplitudes.count > 1 and math.isclose(v1, v2, rel_tol=1e-9):
                raise ValueError(
                    f"amplitudes: start and stop are the same ({self.amplitudes.start}): "
                    f"{self.amplitudes.count} equal amplitudes; give one, or a range"
                )
        return self

    # -- derived --------------------------------------------------------------------------
    @property
    def direction_list(self) -> list[Direction]:
        return ["ltr", "rtl"] if self.directions == "both" else list(self.directions)

    @property
    def amplitude_kind(self) -> AmplitudeKind:
        first = (
            self.amplitudes.start
            if isinstance(self.amplitudes, AmplitudeRange)
            else self.amplitudes[0]
        )
        return parse_amplitude(first)[0]

    def amplitude_values(self) -> NDArray[np.float64]:
        """``[A]`` amplitudes in SI (Vpp or m), in protocol order."""
        a = self.amplitudes
        if isinstance(a, AmplitudeRange):
            lo, hi = parse_amplitude(a.start)[1], parse_amplitude(a.stop)[1]
            if a.spacing == "log":
                return np.geomspace(lo, hi, a.count)
            return np.linspace(lo, hi, a.count)
        return np.array([parse_amplitude(x)[1] for x in a], dtype=np.float64)

    def cylinder_numbers(self, n_cylinders: int) -> NDArray[np.int32]:
        """``[C]`` 1-based cylinder numbers for a chain of ``n_cylinders``."""
        if self.cylinders == "all":
            return np.arange(1, n_cylinders + 1, dtype=np.int32)
        return np.asarray(self.cylinders, dtype=np.int32)

    def output_path(self, when: datetime | None = None) -> Path:
        """The output file from the ``output`` pattern (``{name}``, ``{timestamp}``, ``{date}``)."""
        t = when or datetime.now(UTC)
        return Path(
            self.output.format(
                name=self.name, timestamp=t.strftime("%Y%m%dT%H%M%S"), date=t.strftime("%Y%m%d")
            )
        )


class ProtocolFile:
    """A protocol with its source text and line map (for bench-limit errors with lines)."""

    def __init__(self, protocol: Protocol, doc: YamlDoc) -> None:
        self.protocol = protocol
        self.doc = doc

    @property
    def text(self) -> str:
        return self.doc.text

    def error(self, path: list[str | int] | tuple[str | int, ...], message: str) -> ConfigError:
        return self.doc.error(path, message)


#: top-level keys of a bench file that a protocol never has (one given in its place)
BENCH_KEYS = frozenset({"generator", "vibrometer", "stage", "daq", "amplifier"})


def _validate(doc: YamlDoc) -> ProtocolFile:
    data = doc.data
    if isinstance(data, dict) and len(BENCH_KEYS & set(data)) >= 2 and "burst" not in data:
        raise doc.error(
            (),
            "this is a bench file (it has "
            + ", ".join(sorted(BENCH_KEYS & set(data)))
            + "), not a protocol: give it as --bench BENCH.yaml",
        )
    try:
        return ProtocolFile(validate(doc, Protocol), doc)
    except UnitError as exc:  # raised inside a derived property
        raise doc.error(("amplitudes",), str(exc)) from None


def shipped_protocols() -> dict[str, Path]:
    """The protocol files shipped in ``protocols/``: name (file stem) -> path."""
    here = Path(__file__).resolve().parent
    return {p.stem: p for p in sorted(here.glob("*.yaml"))}


def resolve_protocol_path(path: str | Path) -> Path:
    """``path`` itself when it exists; else a shipped protocol of that name.

    ``run_protocol ltr_highamp.yaml`` (or ``ltr_highamp``) run from any folder finds the shipped
    ``protocols/ltr_highamp.yaml``; a path with a folder part is never looked up elsewhere.
    """
    p = Path(path)
    if p.exists() or p.parent != Path("."):
        return p
    shipped = shipped_protocols()
    stem = p.stem if p.suffix in (".yaml", ".yml") else p.name
    return shipped.get(stem, p)


def load_protocol(path: str | Path) -> ProtocolFile:
    """Load and validate a protocol file (a path, or the name of a shipped protocol, see
    :func:`resolve_protocol_path`); errors are one-line :class:`ConfigError`."""
    p = resolve_protocol_path(path)
    if not p.exists():
        names = ", ".join(shipped_protocols())
        raise ConfigError(f"{path}: no such file, and no shipped protocol of that name ({names})")
    doc = load_yaml(p)
    pf = _validate(doc)
    try:
        pf.protocol.output.format(name="x", timestamp="x", date="x")
    except (KeyError, IndexError, ValueError) as exc:
        msg = f"bad pattern ({exc}); use {{name}}, {{timestamp}}, {{date}}"
        raise doc.error(("output",), msg) from None
    why = output_pattern_problem(pf.protocol.output)
    if why is not None:  # a new protocol's; one stored in a run file is read by parse_protocol
        raise doc.error(("output",), why)  # and stays resumable (runs made before the rule)
    return pf


def names_a_run_file(name: str | Path) -> bool:
    """Whether a new run may be written under ``name``: it ends in .h5, since a run's log is
    ``NAME.log`` beside it (``a.x`` and ``a.y`` would share one; ``x.log`` would be its own)."""
    return Path(name).suffix.lower() == ".h5"


def output_pattern_problem(pattern: str) -> str | None:
    """Why a new run may not take its file name from ``pattern`` (:func:`names_a_run_file`),
    or None."""
    if names_a_run_file(pattern):
        return None
    return (
        f"the output pattern {pattern!r} must end in .h5 (a run's log is written beside it "
        "as NAME.log)"
    )


def parse_protocol(text: str, source: str = "<protocol>") -> ProtocolFile:
    """Validate protocol text (used by ``--resume`` on the text stored in the run file)."""
    return _validate(parse_yaml(text, source))
