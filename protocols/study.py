"""The study file schema: a design study over the chain model, cell by cell.

A study file (YAML) names the design parameters and their ranges, the drive, the model window,
the accuracy to hold and the metrics; ``biafc study STUDY.yaml`` runs one DEM cell per design
point and direction. Example (``protocols/studies/example.yaml``)::

    name: example
    chain: default                    # the base chain: "default" or a chain file (relative
                                      # to the study file); parameters change it cell by cell
    sampling: grid                    # or {latin_hypercube: 500, seed: 1}
    parameters:
      diameter: {from: 12 mm, to: 15 mm, count: 7}        # a range (linear; spacing: log)
      preload: [2 N, 5 N, 10 N]                            # a list of values
      n_cylinders: 11                                      # one value: fixed
    drive:
      directions: [ltr, rtl]
      amplitudes: [1 um, 2 um]        # displacement (um, m) or force (N); crossed with every
                                      # design point (they share its chain: one batch)
      carriers: {ltr: 8.92 kHz, rtl: 6.63 kHz}
      burst: {cycles: 10}             # or {shape: narrowband}
    simulation: {duration: 6 ms, rate: 200 kS/s}
    accuracy: {error_estimate: true, max_error: 1e-3}
    metrics: all                      # or a list of metric names (METRICS)
    run: {cells_per_task: 32}

With ``latin_hypercube`` every parameter is a range ``{from, to}`` (no count) or one fixed
value; the design points are a Latin hypercube of that many samples (scipy.stats.qmc, the seed
given), each whole number of a whole-number parameter's linear range drawn in equal shares
(a log range weights them as the logarithm does).

A cell is one design point at one amplitude; each direction of a cell is one DEM trajectory.
Cells are numbered design point first, amplitude inner (:func:`cell_table`).

Every error is one line ``FILE:LINE: field: message`` (:class:`protocols.yamlfile.ConfigError`):
an unknown parameter names the closest valid one, an empty range and a quantity of the wrong
unit name the field.
"""

from __future__ import annotations

import difflib
import hashlib
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from instruments.units import Duration, SampleRate, UnitError, parse_quantity
from protocols.yamlfile import ConfigError, YamlDoc, load_yaml, parse_yaml, validate

__all__ = [
    "METRICS",
    "PARAMETERS",
    "Axis",
    "CellTable",
    "ParameterInfo",
    "Study",
    "StudyFile",
    "cell_table",
    "load_study",
    "parse_study",
    "shipped_studies",
]

Direction = Literal["ltr", "rtl"]


@dataclass(frozen=True)
class ParameterInfo:
    """A design parameter: its dimension (a key of ``instruments.units.DIMENSIONS``, or
    ``dimensionless``), SI unit, whether it changes the chain or the drive, whole numbers only,
    the smallest allowed value (inclusive unless ``low_open``) and what it is."""

    dimension: str
    unit: str
    target: Literal["chain", "drive"]
    integer: bool = False
    low: float = 0.0
    low_open: bool = True
    high: float = math.inf
    description: str = ""


#: the design parameters a study may vary (name -> info); ``amplitude`` comes from ``drive``
PARAMETERS: dict[str, ParameterInfo] = {
    "diameter": ParameterInfo("length", "m", "chain", description="cylinder diameter"),
    # > 0 N: at 0 N the contacts have no stiffness and no chain can be built (before, 0 N
    # was let through and every cell of it failed at run time)
    "preload": ParameterInfo("force", "N", "chain", description="static pre-compression F0"),
    "length_first": ParameterInfo("length", "m", "chain", description="length of cylinder #1"),
    "length_last": ParameterInfo("length", "m", "chain", description="length of cylinder #N"),
    "n_cylinders": ParameterInfo(
        "dimensionless",
        "",
        "chain",
        integer=True,
        low=2,
        low_open=False,
        high=1000,
        description="number of cylinders N",
    ),
    "n_modes": ParameterInfo(
        "dimensionless",
        "",
        "chain",
        integer=True,
        low=1,
        low_open=False,
        high=12,
        description="bending modes per cylinder J",
    ),
    "alpha": ParameterInfo(
        "dimensionless",
        "",
        "chain",
        low_open=False,
        high=2.0,
        description="asymmetry factor (paper Fig. 4): the centre kept, the profile tilted",
    ),
    "bending_mode_ratio": ParameterInfo(
        "dimensionless",
        "",
        "chain",
        low_open=False,
        high=1.0,
        description="modal damping ratio of the bending modes",
    ),
    "carrier_ltr": ParameterInfo("frequency", "Hz", "drive", description="LTR carrier"),
    "carrier_rtl": ParameterInfo("frequency", "Hz", "drive", description="RTL carrier"),
    "cycles": ParameterInfo("dimensionless", "", "drive", description="burst length, cycles"),
}

#: metric name -> (unit, what it is); per-direction metrics end in ``_ltr``/``_rtl``
METRICS: dict[str, tuple[str, str]] = {
    "transmission": ("", "far-end energy over entry energy, E_far / E_entry, per direction"),
    "asymmetry_ratio": ("", "transmission LTR / transmission RTL"),
    "peak_frequency": ("Hz", "far-end output peak (converted frequency), per direction"),
    "detuning": ("", "(f_out - f_in) / f_in, per direction"),
    "edge_fraction": (
        "",
        "(f_out - f_in) / (f_edge - f_in): 0 unconverted, 1 at the far cylinder's band edge",
    ),
    "efficiency": (
        "",
        "far-end energy on the converted side (beyond 2 sigma_f of the carrier, towards the "
        "edge) over the entry energy, per direction",
    ),
}

_NAMED_BURSTS = ("narrowband", "five_cycle")
_BOTH: tuple[Direction, ...] = ("ltr", "rtl")


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


@dataclass(frozen=True)
class Axis:
    """One parameter's values in SI: ``values`` (a grid axis: a list, a range with a count, or
    one value) or ``low``/``high`` (a Latin-hypercube range); ``spacing`` of a range."""

    name: str
    values: tuple[float, ...] | None
    low: float | None = None
    high: float | None = None
    spacing: Literal["linear", "log"] = "linear"

    @property
    def info(self) -> ParameterInfo:
        return PARAMETERS[self.name]


def _closest(name: str, choices: list[str]) -> str:
    near = difflib.get_close_matches(name, choices, n=1, cutoff=0.5)
    return f" (did you mean {near[0]!r}?)" if near else f" (choose from {', '.join(choices)})"


def _value(name: str, raw: Any, where: str) -> float:
    info = PARAMETERS[name]
    field = f"{name}{where}"
    if info.dimension == "dimensionless":
        if isinstance(raw, bool) or not isinstance(raw, int | float):
            raise ValueError(f"{field}: a plain number (no unit), got {raw!r}")
        v = float(raw)
    else:
        try:
            v = parse_quantity(raw, info.dimension)
        except UnitError as exc:
            raise ValueError(f"{field}: {exc}") from None
    if not math.isfinite(v):
        raise ValueError(f"{field}: must be finite")
    low_ok = v > info.low if info.low_open else v >= info.low
    if not low_ok or v > info.high:
        lo = "(" if info.low_open else "["
        unit = f" {info.unit}" if info.unit else ""
        raise ValueError(f"{field}: {raw!r} is outside {lo}{info.low:g}, {info.high:g}]{unit}")
    if info.integer and v != round(v):
        raise ValueError(f"{field}: a whole number, got {raw!r}")
    return v


def _axis(name: str, raw: Any) -> Axis:
    if isinstance(raw, list):
        if not raw:
            raise ValueError(f"{name}: empty range (give at least one value)")
        vals = tuple(_value(name, x, f".{i}") for i, x in enumerate(raw))
        if len(set(vals)) != len(vals):
            raise ValueError(f"{name}: a value is listed twice")
        return Axis(name, vals)
    if isinstance(raw, dict):
        unknown = [k for k in raw if k not in ("from", "to", "count", "spacing")]
        if unknown:
            k = str(unknown[0])
            msg = f"unknown key{_closest(k, ['from', 'to', 'count', 'spacing'])}"
            raise ValueError(f"{name}.{k}: {msg}")
        for key in ("from", "to"):
            if key not in raw:
                raise ValueError(f"{name}: a range needs 'from' and 'to'")
        lo = _value(name, raw["from"], ".from")
        hi = _value(name, raw["to"], ".to")
        if not hi >= lo:
            raise ValueError(f"{name}.to: empty range ('to' below 'from')")
        spacing = raw.get("spacing", "linear")
        if spacing not in ("linear", "log"):
            raise ValueError(f"{name}.spacing: 'linear' or 'log', got {spacing!r}")
        if spacing == "log" and not lo > 0:
            raise ValueError(f"{name}.spacing: log spacing needs 'from' > 0")
        if "count" not in raw:
            if hi == lo:
                return Axis(name, (lo,))
            return Axis(name, None, lo, hi, spacing)
        count = raw["count"]
        if isinstance(count, bool) or not isinstance(count, int):
            raise ValueError(f"{name}.count: a whole number, got {count!r}")
        if count < 1:
            raise ValueError(f"{name}.count: empty range (count must be >= 1, got {count})")
        if count > 1 and hi == lo:
            raise ValueError(f"{name}.to: empty range ('from' equals 'to' with count {count})")
        if count > 100_000:
            raise ValueError(f"{name}.count: at most 100000, got {count}")
        grid = np.geomspace(lo, hi, count) if spacing == "log" else np.linspace(lo, hi, count)
        if PARAMETERS[name].integer:
            grid = np.unique(np.round(grid))
        return Axis(name, tuple(float(x) for x in grid), lo, hi, spacing)
    return Axis(name, (_value(name, raw, ""),))


class Sampling(_Model):
    """``grid`` (every combination) or a Latin hypercube of ``latin_hypercube`` samples."""

    latin_hypercube: int = Field(ge=1, le=10_000_000)
    seed: int = Field(default=0, ge=0)


class BurstChoice(_Model):
    """The burst shape: ``cycles`` in the window, or a named shape."""

    cycles: float | None = None
    shape: str | None = None

    @model_validator(mode="after")
    def _one(self) -> BurstChoice:
        if (self.cycles is None) == (self.shape is None):
            raise ValueError("give exactly one of 'cycles' or 'shape'")
        if self.cycles is not None and not (math.isfinite(self.cycles) and self.cycles > 0):
            raise ValueError("cycles: must be > 0")
        if self.shape is not None and self.shape not in _NAMED_BURSTS:
            raise ValueError(f"shape: one of {', '.join(_NAMED_BURSTS)}, got {self.shape!r}")
        return self


class DriveSpec(_Model):
    """Directions, amplitudes (all displacements or all forces, SI in :attr:`amplitude_values`),
    carriers per direction (Hz) and the burst."""

    directions: list[Direction] = Field(default_factory=lambda: list(_BOTH))
    amplitudes: Any
    carriers: dict[Direction, Any] = Field(default_factory=dict)
    burst: BurstChoice = BurstChoice(shape="narrowband")

    @field_validator("directions")
    @classmethod
    def _dirs(cls, v: list[str]) -> list[str]:
        if not v:
            raise ValueError("give at least one direction (ltr, rtl)")
        if len(set(v)) != len(v):
            raise ValueError("a direction is listed twice")
        return v

    @field_validator("amplitudes")
    @classmethod
    def _amps(cls, v: Any) -> Any:
        _amplitude_axis(v)
        return v

    @field_validator("carriers")
    @classmethod
    def _carriers(cls, v: dict[str, Any]) -> dict[str, float]:
        out = {}
        for d, raw in v.items():
            try:
                f = parse_quantity(raw, "frequency")
            except UnitError as exc:
                raise ValueError(f"{d}: {exc}") from None
            if not f > 0:
                raise ValueError(f"{d}: must be > 0 Hz")
            out[d] = f
        return out

    def amplitude_kind(self) -> Literal["displacement", "force"]:
        return _amplitude_axis(self.amplitudes)[0]

    def amplitude_values(self) -> tuple[float, ...]:
        """Amplitudes in SI (m or N)."""
        return _amplitude_axis(self.amplitudes)[1]

    def carrier(self, direction: str) -> float:
        """Carrier (Hz) of ``direction``: given, or the paper's (8.92 kHz LTR, 6.63 kHz RTL)."""
        given: dict[str, Any] = {str(k): v for k, v in self.carriers.items()}
        return float(given.get(direction, _PAPER_CARRIERS[direction]))


_PAPER_CARRIERS = {"ltr": 8920.0, "rtl": 6630.0}


def _amplitude(raw: Any, where: str) -> tuple[Literal["displacement", "force"], float]:
    try:
        v = parse_quantity(raw, "length")
        kind: Literal["displacement", "force"] = "displacement"
    except UnitError:
        try:
            v = parse_quantity(raw, "force")
            kind = "force"
        except UnitError:
            raise ValueError(
                f"{where}: {raw!r} is neither a displacement ('2 um') nor a force ('5 N')"
            ) from None
    if not (math.isfinite(v) and v > 0):
        raise ValueError(f"{where}: must be > 0, got {raw!r}")
    return kind, v


def _amplitude_axis(raw: Any) -> tuple[Literal["displacement", "force"], tuple[float, ...]]:
    if isinstance(raw, dict):
        unknown = [k for k in raw if k not in ("from", "to", "count", "spacing")]
        if unknown:
            raise ValueError(f"{unknown[0]}: unknown key (from, to, count, spacing)")
        if "from" not in raw or "to" not in raw or "count" not in raw:
            raise ValueError("a range of amplitudes needs 'from', 'to' and 'count'")
        k0, lo = _amplitude(raw["from"], "from")
        k1, hi = _amplitude(raw["to"], "to")
        if k0 != k1:
            raise ValueError("to: 'from' and 'to' must both be displacements or both forces")
        count = raw["count"]
        if isinstance(count, bool) or not isinstance(count, int) or count < 1:
            raise ValueError(f"count: empty range (a whole number >= 1, got {count!r})")
        if not hi >= lo or (count > 1 and hi == lo):
            raise ValueError("to: empty range ('to' must be above 'from')")
        spacing = raw.get("spacing", "linear")
        if spacing not in ("linear", "log"):
            raise ValueError(f"spacing: 'linear' or 'log', got {spacing!r}")
        grid = np.geomspace(lo, hi, count) if spacing == "log" else np.linspace(lo, hi, count)
        return k0, tuple(float(x) for x in grid)
    items = raw if isinstance(raw, list) else [raw]
    if not items:
        raise ValueError("empty range (give at least one amplitude)")
    parsed = [_amplitude(x, f"[{i}]") for i, x in enumerate(items)]
    kinds = {k for k, _ in parsed}
    if len(kinds) != 1:
        raise ValueError("give all amplitudes as displacements or all as forces")
    vals = tuple(v for _, v in parsed)
    if len(set(vals)) != len(vals):
        raise ValueError("an amplitude is listed twice")
    return parsed[0][0], vals


class SimulationSpec(_Model):
    """The model's window: recorded duration (s), record rate (S/s), integrator, step (s)."""

    duration: Duration
    rate: SampleRate = 200_000.0
    integrator: str = "default"
    dt: Duration | None = None

    @model_validator(mode="after")
    def _check(self) -> SimulationSpec:
        if not self.duration > 0:
            raise ValueError("duration: must be > 0")
        if not self.rate > 0:
            raise ValueError("rate: must be > 0")
        if self.dt is not None and not self.dt > 0:
            raise ValueError("dt: must be > 0")
        if self.duration * self.rate > 1.0e6:
            raise ValueError("duration: more than 1e6 samples per trajectory; shorten it")
        return self


class AccuracySpec(_Model):
    """The accuracy to hold: the integrator's step-doubling error estimate is recorded per cell
    (``error_estimate``, about half the run time again) and a cell above ``max_error``
    (relative L2 of the velocity, worst recorded cylinder) is flagged."""

    error_estimate: bool = True
    max_error: float = Field(default=1.0e-3, gt=0.0, le=1.0)


class RunSpec(_Model):
    """How cells are grouped: ``cells_per_task`` cells per task (cells of one chain in one
    batched sweep)."""

    cells_per_task: int = Field(default=32, ge=1, le=100_000)


class Study(_Model):
    """A validated study (see the module docstring). Quantities are SI floats."""

    name: str = Field(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9][A-Za-z0-9._-]*$")
    description: str = ""
    chain: str = "default"
    sampling: Literal["grid"] | Sampling = "grid"
    parameters: dict[str, Axis]
    drive: DriveSpec
    simulation: SimulationSpec
    accuracy: AccuracySpec = AccuracySpec()
    metrics: Literal["all"] | list[str] = "all"
    record_spectra: bool = False
    run: RunSpec = RunSpec()

    @field_validator("parameters", mode="before")
    @classmethod
    def _parameters(cls, v: Any) -> dict[str, Axis]:
        if not isinstance(v, dict):
            raise ValueError("a mapping of parameter names to values or ranges")
        if not v:
            raise ValueError("name at least one parameter")
        out: dict[str, Axis] = {}
        for name, raw in v.items():
            key = str(name)
            if key not in PARAMETERS:
                hint = _closest(key, list(PARAMETERS))
                if key in ("amplitude", "amplitudes"):
                    hint = " (amplitudes are given under drive.amplitudes)"
                raise ValueError(f"{key}: unknown parameter{hint}")
            out[key] = _axis(key, raw)
        if "alpha" in out and ({"length_first", "length_last"} & set(out)):
            raise ValueError("alpha: sets the lengths itself; drop length_first/length_last")
        return out

    @field_validator("metrics")
    @classmethod
    def _metrics(cls, v: Any) -> Any:
        if isinstance(v, list):
            if not v:
                raise ValueError("give at least one metric, or 'all'")
            for m in v:
                if m not in METRICS:
                    raise ValueError(f"{m!r}: unknown metric{_closest(str(m), list(METRICS))}")
        return v

    @field_validator("sampling", mode="before")
    @classmethod
    def _sampling_count(cls, v: Any) -> Any:
        """A bad sample count is named as such (the union's error said "Input should be
        'grid'")."""
        n = v.get("latin_hypercube") if isinstance(v, dict) else None
        if isinstance(n, int | float) and not isinstance(n, bool) and not 1 <= n <= 10_000_000:
            raise ValueError(f"latin_hypercube: give 1 to 10000000 samples, got {n!r}")
        return v

    @model_validator(mode="after")
    def _sampling(self) -> Study:
        lhs = not isinstance(self.sampling, str)
        if lhs and all(a.values is not None for a in self.parameters.values()):
            raise ValueError(
                "sampling: a Latin hypercube needs a parameter given as a range {from, to}; "
                "with fixed values only every sample is the same cell (use sampling: grid)"
            )
        for name, axis in self.parameters.items():
            if lhs and axis.values is not None and len(axis.values) > 1:
                raise ValueError(
                    f"parameters.{name}: with latin_hypercube give a range {{from, to}} "
                    "without count, or one value"
                )
            if not lhs and axis.values is None:
                raise ValueError(
                    f"parameters.{name}: a grid needs values: add 'count' to the range"
                )
        for d in self.drive.carriers:
            if d not in self.drive.directions:
                raise ValueError(f"drive.carriers: {d} is not among drive.directions")
        for d in ("ltr", "rtl"):
            if f"carrier_{d}" in self.parameters and d in self.drive.carriers:
                raise ValueError(f"drive.carriers: carrier_{d} is a parameter already")
        named = "burst" in self.drive.model_fields_set and self.drive.burst.shape is not None
        if "cycles" in self.parameters and named:  # the default shape is no one's choice
            raise ValueError("drive.burst: cycles is a parameter; drop the named shape")
        if self.metrics != "all" and "asymmetry_ratio" in self.metrics:
            if set(self.drive.directions) != {"ltr", "rtl"}:
                raise ValueError("metrics: asymmetry_ratio needs both directions")
        return self

    @model_validator(mode="after")
    def _drive_fits_the_record(self) -> Study:
        """Every burst the study plays (each carrier value, each cycles value) within the
        record: :func:`protocols.model_request.model_request_error`, the checks ``biafc
        simulate`` makes, and the whole burst within the window (the metrics integrate it)."""
        why = drive_request_error(self)
        if why is not None:
            raise ValueError(f"{why[0]}: {why[1]}")
        return self

    def metric_names(self) -> list[str]:
        """Stored metric datasets, per direction where the metric is one (``transmission_ltr``)."""
        chosen = list(METRICS) if self.metrics == "all" else list(self.metrics)
        out: list[str] = []
        for m in chosen:
            if m == "asymmetry_ratio":
                if set(self.drive.directions) == {"ltr", "rtl"}:
                    out.append(m)
            else:
                out.extend(f"{m}_{d}" for d in self.drive.directions)
        return out

    def results_json(self) -> str:
        """Canonical JSON of everything that decides a cell's result (not ``name``,
        ``description`` or ``run``): what :attr:`StudyFile.digest` hashes."""
        data = self.model_dump(mode="json", exclude={"name", "description", "run"})
        if not isinstance(self.sampling, str) and any(
            a.info.integer and a.values is None for a in self.parameters.values()
        ):  # whole numbers drawn in equal shares since 2026-11-28 (rounded before): a study
            # begun before is another study, not continued with other cells
            data["whole_numbers"] = "equal shares"
        data["parameters"] = {
            k: {"values": list(a.values) if a.values is not None else None,
                "low": a.low, "high": a.high, "spacing": a.spacing}
            for k, a in sorted(self.parameters.items())
        }  # fmt: skip
        return json.dumps(data, sort_keys=True)


def _axis_values(axis: Axis) -> tuple[float, ...]:
    """Every value of a grid axis, or both ends of a Latin-hypercube range."""
    if axis.values is not None:
        return axis.values
    assert axis.low is not None and axis.high is not None
    return (axis.low, axis.high)


def drive_request_error(study: Study) -> tuple[str, str] | None:
    """The first burst of ``study`` its record cannot hold, as ``(field, why)`` (the dotted
    field of the study file that set it), or None. Every carrier value is checked (a carrier
    that is a parameter: each value; with a Latin hypercube, both ends of its range), each at
    the fewest and the most cycles the study plays, and every cycles value at the lowest and
    the highest carrier (each check is monotonic in either number, so no pair in between can
    fail where these pass)."""
    from instruments.burst import NAMED_BURSTS, Burst
    from protocols.model_request import RequestNames, model_request_error

    sim = study.simulation
    burst_choice = study.drive.burst
    if "cycles" in study.parameters:
        cycles_field = "parameters.cycles"
        cycles = _axis_values(study.parameters["cycles"])
    else:
        cycles_field = "drive.burst"
        n = burst_choice.cycles
        cycles = (n if n is not None else NAMED_BURSTS[str(burst_choice.shape)],)
    longest: tuple[Burst, RequestNames] | None = None
    for d in study.drive.directions:
        carrier_axis = study.parameters.get(f"carrier_{d}")
        if carrier_axis is not None:
            freq_field: str | None = f"parameters.carrier_{d}"
            carriers = _axis_values(carrier_axis)
        else:
            freq_field = f"drive.carriers.{d}" if d in study.drive.carriers else None
            carriers = (study.drive.carrier(d),)
        names = RequestNames(
            duration="simulation.duration",
            rate="simulation.rate",
            frequency=freq_field,
            burst=cycles_field,
            cycles=cycles_field,
        )
        pairs = [(f, n) for f in carriers for n in {min(cycles), max(cycles)}]
        pairs += [(f, n) for n in cycles for f in {min(carriers), max(carriers)}]
        for f, n in pairs:
            why = model_request_error(sim.duration, sim.rate, Burst(f, cycles=n), None, names)
            if why is not None:
                return why
        burst = Burst(min(carriers), cycles=max(cycles))  # this direction's longest
        if longest is None or burst.duration_s > longest[0].duration_s:
            longest = burst, names
    assert longest is not None  # the directions are never empty
    # the window against the longest burst of all: the least window it could have is said
    return model_request_error(
        sim.duration, sim.rate, longest[0], None, longest[1], whole_burst=True
    )


@dataclass(frozen=True)
class StudyFile:
    """A loaded study: the model, the YAML document (lines for errors), the study text, and the
    base chain's resolved path (``None``: the default chain)."""

    study: Study
    doc: YamlDoc
    chain_path: Path | None

    @property
    def text(self) -> str:
        return self.doc.text

    def error(self, path: tuple[str | int, ...], message: str) -> ConfigError:
        """A one-line error at ``path``'s line of the study file."""
        return self.doc.error(path, message)

    def digest(self, chain_yaml: str) -> str:
        """sha256 of the study's result-deciding content and the base chain (its YAML)."""
        h = hashlib.sha256()
        h.update(self.study.results_json().encode())
        h.update(b"\0")
        h.update(chain_yaml.encode())
        return h.hexdigest()


def _finish(doc: YamlDoc, base_dir: Path | None) -> StudyFile:
    study = validate(doc, Study)
    chain_path: Path | None = None
    if study.chain != "default":
        p = Path(study.chain)
        if not p.is_absolute() and base_dir is not None:
            p = base_dir / p
        if not p.is_file():
            raise doc.error(("chain",), f"no chain file {study.chain!r} ('default' or a file)")
        chain_path = p
    return StudyFile(study, doc, chain_path)


def load_study(path: str | Path) -> StudyFile:
    """Load and validate a study file (a path, or the name of a shipped study); errors are
    one-line :class:`ConfigError` ``FILE:LINE: field: message``."""
    p = Path(path)
    if not p.exists() and p.suffix == "" and (_SHIPPED / f"{p}.yaml").exists():
        p = _SHIPPED / f"{p}.yaml"
    if not p.exists():
        raise ConfigError(f"{path}: no such study file")
    return _finish(load_yaml(p), p.parent)


def parse_study(text: str, source: str = "<study>", base_dir: Path | None = None) -> StudyFile:
    """Validate study text (the copy stored in a study output, or a test's)."""
    return _finish(parse_yaml(text, source), base_dir)


_SHIPPED = Path(__file__).with_name("studies")


def shipped_studies() -> list[str]:
    """Names of the studies shipped in ``protocols/studies``."""
    return sorted(p.stem for p in _SHIPPED.glob("*.yaml"))


@dataclass(frozen=True)
class CellTable:
    """Every cell of a study: ``names [P]`` (parameters, ``amplitude`` last), ``values [n, P]``
    (SI), ``point [n]`` (the design point of each cell), ``amplitude_kind``."""

    names: tuple[str, ...]
    values: NDArray[np.float64]
    point: NDArray[np.int64]
    amplitude_kind: str

    @property
    def n_cells(self) -> int:
        return int(self.values.shape[0])

    def column(self, name: str) -> NDArray[np.float64]:
        return self.values[:, self.names.index(name)]

    def row(self, i: int) -> dict[str, float]:
        return {n: float(v) for n, v in zip(self.names, self.values[i], strict=True)}


def _design_points(study: Study) -> tuple[list[str], NDArray[np.float64]]:
    names = list(study.parameters)
    axes = [study.parameters[n] for n in names]
    if isinstance(study.sampling, str):
        grids = [np.asarray(a.values, dtype=np.float64) for a in axes]
        mesh = np.meshgrid(*grids, indexing="ij")
        return names, np.stack([m.ravel() for m in mesh], axis=1)
    from scipy.stats import qmc

    n = study.sampling.latin_hypercube
    ranged = [i for i, a in enumerate(axes) if a.values is None]
    pts = np.empty((n, len(axes)))
    if ranged:
        gen = np.random.default_rng(study.sampling.seed)
        try:
            lhs = qmc.LatinHypercube(d=len(ranged), rng=gen)
        except TypeError:  # scipy < 1.15
            lhs = qmc.LatinHypercube(d=len(ranged), seed=gen)
        sample = lhs.random(n)
        for j, i in enumerate(ranged):
            a = axes[i]
            assert a.low is not None and a.high is not None
            if a.spacing == "log":
                col = np.exp(np.log(a.low) + sample[:, j] * (np.log(a.high) - np.log(a.low)))
            else:
                col = a.low + sample[:, j] * (a.high - a.low)
            if a.info.integer:  # each whole number its equal share of the samples (rounding
                # gave the two ends half a share each: 6/14/13/7 of 40 for 5..8)
                top = a.high + 1.0
                if a.spacing == "log":
                    col = np.exp(np.log(a.low) + sample[:, j] * (np.log(top) - np.log(a.low)))
                else:
                    col = a.low + sample[:, j] * (top - a.low)
                col = np.minimum(np.floor(col), a.high)
            pts[:, i] = col
    for i, a in enumerate(axes):
        if a.values is not None:
            pts[:, i] = a.values[0]
    return names, pts


def cell_table(study: Study) -> CellTable:
    """The study's cells in their fixed order: design points (grid in C order of the
    parameters as written, or the Latin hypercube's samples), each at every amplitude."""
    names, pts = _design_points(study)
    amps = np.asarray(study.drive.amplitude_values(), dtype=np.float64)
    n_pts, n_amp = pts.shape[0], amps.size
    values = np.empty((n_pts * n_amp, len(names) + 1))
    values[:, :-1] = np.repeat(pts, n_amp, axis=0)
    values[:, -1] = np.tile(amps, n_pts)
    point = np.repeat(np.arange(n_pts, dtype=np.int64), n_amp)
    return CellTable((*names, "amplitude"), values, point, study.drive.amplitude_kind())
