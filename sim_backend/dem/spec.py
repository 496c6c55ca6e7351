"""The chain file (YAML): a pydantic model whose quantities carry units.

Example (the default chain, ``sim_backend/dem/chains/default.yaml``)::

    n_cylinders: 31
    length_first: 90 mm      # cylinder #1 (the LTR entry)
    length_last: 110 mm      # cylinder #N; lengths graded linearly in between
    diameter: 13.6 mm
    preload: 5 N
    n_modes: 3
    beam_theory: timoshenko
    material: {youngs_modulus: 72 GPa, density: 2200 kg/m^3, poisson_ratio: 0.17}
    far_end: wall            # wall (rigid Hertz wall) | free (constant preload force)
    damping: {bending_mode_ratio: 0.002, contact_dashpot_ratio: 0}
    crossing_angle: 90 deg   # orientation of neighbours (90 deg: woodpile); elliptical Hertz else

Optional, for stiff and extreme variants (``biafc stability``); absent = the plain chain:

    contact_stiffness_factor: 11.18  # multiplies beta_c (K at fixed F0 scales as factor^(2/3))
    density_factors: {16: 10}        # cylinder number -> density factor (mass x f, w_j / sqrt(f))
    contact_gaps: {16: 2 um}         # contact number k (#k-#k+1) -> gap at rest; needs preload 0 N

``preload: 0 N`` is allowed (no pre-compression, zero linear stiffness: the "sonic vacuum"); the
contact dashpot is the linearised one at the preload, so it then needs ``contact_dashpot_ratio: 0``.

Any setting can also be given as ``KEY=VALUE`` (``diameter=12mm``, ``preload=4N``,
``n_modes=5``, ``damping.contact_dashpot_ratio=0.005``; dotted keys reach nested ones) with
:func:`apply_settings` (``--set`` of ``biafc simulate``, ``biafc bands`` and the simulated
bench's ``chain_set``); the result is validated exactly like a chain file.

``lengths: [90 mm, 91 mm, ...]`` may replace ``n_cylinders``/``length_first``/``length_last``.
A bad file raises :class:`ChainFileError` with one line naming the file and the field.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Literal

import numpy as np
import yaml
from numpy.typing import NDArray
from pydantic import (
    AliasChoices,
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    field_validator,
    model_validator,
)

from instruments.units import Angle, Density, Force, Length, Pressure
from sim_backend.dem.contact import MIN_CROSSING_ANGLE_RAD
from sim_backend.dem.material import Material

__all__ = [
    "ChainFileError",
    "ChainSpec",
    "DampingSpec",
    "MaterialSpec",
    "apply_settings",
    "benchmark_chain_spec",
    "default_chain_path",
    "default_chain_spec",
    "load_chain_spec",
    "load_chain_with_settings",
]


class ChainFileError(ValueError):
    """A chain file or chain setting that cannot be used (one line, names file and field)."""


class MaterialSpec(BaseModel):
    """Material of the cylinders (quantities with units in YAML)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    name: str = "fused quartz"
    youngs_modulus: Pressure = 72.0e9
    density: Density = 2200.0
    poisson_ratio: float = 0.17

    @field_validator("youngs_modulus", "density")
    @classmethod
    def _positive(cls, v: float) -> float:
        if not v > 0:
            raise ValueError("must be > 0")
        return v

    @field_validator("poisson_ratio")
    @classmethod
    def _poisson(cls, v: float) -> float:
        if not -1.0 < v < 0.5:
            raise ValueError("must be in (-1, 0.5)")
        return v

    def to_material(self) -> Material:
        """The SI :class:`Material`."""
        return Material(self.name, self.youngs_modulus, self.density, self.poisson_ratio)


class DampingSpec(BaseModel):
    """Damping ratios (dimensionless), each named for what it acts on.

    ``bending_mode_ratio``: modal damping ratio of every cylinder's free-free symmetric bending
    modes (the modes of the contact-free block, primary mass plus resonators, whose frequencies
    are the band onsets); the rigid translation is not damped. Default 0.002, an assumed value
    in the 1e-3 to 1e-2 range of the paper's supplementary material (no measurement of these
    cylinders behind it). ``contact_dashpot_ratio``: the Hunt-Crossley dashpot of every contact,
    as the damping ratio of the linearised contact (``c = 2 zeta sqrt(K m0)``); default 0, since
    no measurement supports a value (0.005 halved the RTL gain at 2 um).
    The old names ``resonator_ratio`` and ``contact_ratio`` are read as these.
    """

    model_config = ConfigDict(extra="forbid", frozen=True, populate_by_name=True)

    bending_mode_ratio: float = Field(
        default=2.0e-3,
        ge=0.0,
        lt=1.0,
        validation_alias=AliasChoices("bending_mode_ratio", "resonator_ratio"),
    )
    contact_dashpot_ratio: float = Field(
        default=0.0,
        ge=0.0,
        lt=1.0,
        validation_alias=AliasChoices("contact_dashpot_ratio", "contact_ratio"),
    )


class ChainSpec(BaseModel):
    """A graded cylinder chain. SI floats inside; YAML values carry units."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    n_cylinders: int | None = Field(default=None, ge=1, le=10_000)
    length_first: Length | None = None
    length_last: Length | None = None
    lengths: tuple[Length, ...] | None = None
    diameter: Length = 13.6e-3
    preload: Force = 5.0
    n_modes: int = Field(default=3, ge=1, le=12)
    beam_theory: Literal["timoshenko", "euler-bernoulli"] = "timoshenko"
    material: MaterialSpec = MaterialSpec()
    far_end: Literal["wall", "free"] = "wall"
    damping: DampingSpec = DampingSpec()
    crossing_angle: Angle = 0.5 * math.pi
    contact_stiffness_factor: float = Field(default=1.0, gt=0.0, le=1.0e6)
    density_factors: dict[int, float] | None = None
    contact_gaps: dict[int, Length] | None = None

    @field_validator("length_first", "length_last", "diameter")
    @classmethod
    def _positive(cls, v: float | None) -> float | None:
        if v is not None and not v > 0:
            raise ValueError("must be > 0")
        return v

    @field_validator("preload")
    @classmethod
    def _non_negative(cls, v: float) -> float:
        if not (math.isfinite(v) and v >= 0):
            raise ValueError("must be >= 0")
        return v

    @field_validator("crossing_angle")
    @classmethod
    def _crossing(cls, v: float) -> float:
        low = MIN_CROSSING_ANGLE_RAD
        if not low <= v <= math.pi - low:
            lo = math.degrees(low)
            raise ValueError(f"must be in [{lo:.3g}, {180 - lo:.3g}] deg (90 deg: the woodpile)")
        return v

    @field_validator("contact_stiffness_factor")
    @classmethod
    def _finite(cls, v: float) -> float:
        if not math.isfinite(v):
            raise ValueError("must be finite")
        return v

    @field_validator("density_factors")
    @classmethod
    def _density_factors(cls, v: dict[int, float] | None) -> dict[int, float] | None:
        if v is not None:
            for k, f in v.items():
                if not (math.isfinite(f) and 0 < f <= 1.0e6):
                    raise ValueError(f"factor of cylinder #{k} must be in (0, 1e6]")
        return v

    @field_validator("contact_gaps")
    @classmethod
    def _gaps(cls, v: dict[int, float] | None) -> dict[int, float] | None:
        if v is not None:
            for k, g in v.items():
                if not (math.isfinite(g) and g >= 0):
                    raise ValueError(f"gap of contact {k} must be >= 0")
        return v

    @field_validator("lengths")
    @classmethod
    def _lengths_positive(cls, v: tuple[float, ...] | None) -> tuple[float, ...] | None:
        if v is not None:
            if len(v) < 1:
                raise ValueError("needs at least 1 cylinder")
            for i, x in enumerate(v):
                if not x > 0:
                    raise ValueError(f"length of cylinder #{i + 1} must be > 0")
        return v

    @model_validator(mode="after")
    def _one_geometry(self) -> ChainSpec:
        graded = (self.n_cylinders, self.length_first, self.length_last)
        if self.lengths is not None:
            if any(x is not None for x in graded):
                raise ValueError("give either lengths or n_cylinders/length_first/length_last")
        elif any(x is None for x in graded):
            raise ValueError("give lengths, or all of n_cylinders, length_first, length_last")
        n = self.n
        for k in self.density_factors or {}:
            if not 1 <= k <= n:
                raise _FieldError("density_factors", f"cylinder #{k} is not in 1..{n}")
        for k in self.contact_gaps or {}:
            if not 1 <= k <= n - 1:
                raise _FieldError("contact_gaps", f"contact {k} is not in 1..{n - 1} (#k-#k+1)")
        if self.contact_gaps and any(g > 0 for g in self.contact_gaps.values()):
            if self.preload > 0:
                raise _FieldError(
                    "contact_gaps", "needs preload 0 N (a preloaded chain cannot rest open)"
                )
        if self.preload == 0 and self.damping.contact_dashpot_ratio > 0:
            raise _FieldError(
                "damping.contact_dashpot_ratio",
                "must be 0 with preload 0 N (the dashpot is the linearised one at the preload)",
            )
        return self

    def lengths_m(self) -> NDArray[np.float64]:
        """[N] cylinder lengths in m, #1 first."""
        if self.lengths is not None:
            return np.asarray(self.lengths, dtype=np.float64)
        assert self.n_cylinders is not None
        assert self.length_first is not None and self.length_last is not None
        return np.linspace(self.length_first, self.length_last, self.n_cylinders)

    @property
    def n(self) -> int:
        """Number of cylinders."""
        return len(self.lengths_m())

    def to_yaml(self) -> str:
        """The spec as a chain file (explicit lengths, quantities with units)."""
        data: dict[str, Any] = {
            "lengths": [f"{x * 1e3:.9g} mm" for x in self.lengths_m()],
            "diameter": f"{self.diameter * 1e3:.9g} mm",
            "preload": f"{self.preload:.9g} N",
            "n_modes": self.n_modes,
            "beam_theory": self.beam_theory,
            "material": {
                "name": self.material.name,
                "youngs_modulus": f"{self.material.youngs_modulus / 1e9:.9g} GPa",
                "density": f"{self.material.density:.9g} kg/m^3",
                "poisson_ratio": self.material.poisson_ratio,
            },
            "far_end": self.far_end,
            "damping": self.damping.model_dump(),
        }
        if self.crossing_angle != 0.5 * math.pi:
            data["crossing_angle"] = f"{math.degrees(self.crossing_angle):.9g} deg"
        if self.contact_stiffness_factor != 1.0:
            data["contact_stiffness_factor"] = self.contact_stiffness_factor
        if self.density_factors:
            data["density_factors"] = dict(self.density_factors)
        if self.contact_gaps:
            data["contact_gaps"] = {k: f"{g * 1e6:.9g} um" for k, g in self.contact_gaps.items()}
        return yaml.safe_dump(data, sort_keys=False)


class _FieldError(ValueError):
    """A cross-field error of :class:`ChainSpec` that names its field (``field: message``)."""

    def __init__(self, field: str, message: str) -> None:
        super().__init__(f"{field}: {message}")


def _first_error(exc: ValidationError, data: Any = None) -> str:
    errors = exc.errors()
    unknown = [e for e in errors if e.get("type") == "extra_forbidden"]
    err = unknown[0] if unknown else errors[0]  # a misspelt key also leaves its field missing
    loc = ".".join(str(p) for p in err.get("loc", ()))
    msg = str(err.get("msg", "invalid"))
    msg = msg.removeprefix("Value error, ")
    if not loc:  # a cross-field check: its message names the field (or the top level)
        return (
            msg
            if isinstance(err.get("ctx", {}).get("error"), _FieldError)
            else f"(top level): {msg}"
        )
    if err.get("type") == "extra_forbidden":
        from protocols.yamlfile import unknown_key_message

        msg = unknown_key_message(data, ChainSpec, tuple(err["loc"]), errors)
    return f"{loc}: {msg}"


def chain_spec_from_dict(data: Any, source: str = "chain") -> ChainSpec:
    """Validate a mapping (as read from YAML) into a :class:`ChainSpec`."""
    if not isinstance(data, dict):
        raise ChainFileError(f"{source}: expected a mapping of chain settings")
    try:
        return ChainSpec.model_validate(data)
    except ValidationError as exc:
        raise ChainFileError(f"{source}: {_first_error(exc, data)}") from None


def load_chain_spec(path: str | Path) -> ChainSpec:
    """Read a chain file (YAML). Raises :class:`ChainFileError` (one line: file and field)."""
    p = Path(path)
    return chain_spec_from_dict(_read_chain_file(p), str(p))


def _read_chain_file(p: Path) -> Any:
    """The data of a chain file, read by the bounded settings-file loader (size, text,
    nesting, aliases: :mod:`protocols.yamlfile`); its refusals become :class:`ChainFileError`."""
    from protocols.yamlfile import ConfigError, read_yaml_data

    try:
        return read_yaml_data(p)
    except ConfigError as exc:
        raise ChainFileError(str(exc)) from None


def default_chain_path() -> Path:
    """Path of the shipped default chain file."""
    return Path(__file__).with_name("chains") / "default.yaml"


def default_chain_spec() -> ChainSpec:
    """The paper's chain: 31 fused-quartz cylinders 90 -> 110 mm, d = 13.6 mm, F0 = 5 N, J = 3."""
    return load_chain_spec(default_chain_path())


_GRADED = ("n_cylinders", "length_first", "length_last")


def _raw_chain_dict(path: str | Path | None) -> tuple[dict[str, Any], str]:
    p = Path(path) if path is not None else default_chain_path()
    data = _read_chain_file(p)
    if not isinstance(data, dict):
        raise ChainFileError(f"{p}: expected a mapping of chain settings")
    return data, str(p)


def _setting_value(text: str, source: str) -> Any:
    """The value of one ``KEY=VALUE`` read as YAML by the bounded loader (no alias expansion
    beyond its bound); text that is not YAML stays text."""
    from protocols.yamlfile import ConfigError, InputBoundError, parse_yaml

    try:
        return parse_yaml(text, source).data
    except InputBoundError as exc:
        raise ChainFileError(str(exc)) from None
    except ConfigError:
        return text.strip()


def _groups_holding(key: str) -> list[str]:
    """Names of the chain's groups of settings (``damping``, ``material``) that hold ``key``."""
    out = []
    for name, info in ChainSpec.model_fields.items():
        ann = info.annotation
        if isinstance(ann, type) and issubclass(ann, BaseModel) and key in ann.model_fields:
            out.append(name)
    return out


def apply_settings(
    data: dict[str, Any], settings: list[str] | tuple[str, ...], source: str = "--set"
) -> dict[str, Any]:
    """A copy of the chain mapping ``data`` (as read from YAML) with every ``KEY=VALUE`` of
    ``settings`` applied; values are read as YAML scalars (``12mm``, ``4 N``, ``5``, ``wall``).
    A dotted key (``damping.contact_dashpot_ratio``) sets a nested one. Setting a graded-length
    key drops an explicit ``lengths`` list, and setting ``lengths`` drops the graded keys."""
    out: dict[str, Any] = {k: (dict(v) if isinstance(v, dict) else v) for k, v in data.items()}
    for item in settings:
        key, sep, text = item.partition("=")
        key = key.strip()
        if not sep or not key or not text.strip():
            raise ChainFileError(f"{source} {item!r}: write KEY=VALUE, e.g. diameter=12mm")
        value = _setting_value(text, f"{source} {key}")
        if "." not in key and key not in ChainSpec.model_fields:
            groups = _groups_holding(key)
            if groups:  # the generic near-name hint would name an unrelated top-level key
                dotted = " or ".join(f"{g}.{key}" for g in groups)
                raise ChainFileError(
                    f"{source} {item!r}: {key} is a setting inside a group; write {dotted}"
                )
        parts = key.split(".")
        target = out
        for part in parts[:-1]:
            sub = target.get(part)
            if sub is None:
                sub = {}
            if not isinstance(sub, dict):
                raise ChainFileError(f"{source} {item!r}: {part} is not a group of settings")
            target[part] = sub = dict(sub)
            target = sub
        target[parts[-1]] = value
        if len(parts) == 1 and key in _GRADED:
            out.pop("lengths", None)
        if len(parts) == 1 and key == "lengths":
            for k in _GRADED:
                out.pop(k, None)
    return out


def load_chain_with_settings(
    path: str | Path | None = None, settings: list[str] | tuple[str, ...] = ()
) -> ChainSpec:
    """The chain file at ``path`` (default: the shipped chain) with ``KEY=VALUE`` settings
    applied (:func:`apply_settings`), validated like a chain file. Errors are one line naming
    the file, the settings and the field."""
    data, source = _raw_chain_dict(path)
    if not settings:
        return chain_spec_from_dict(data, source)
    merged = apply_settings(data, settings)
    return chain_spec_from_dict(merged, f"{source} with --set {' '.join(settings)}")


#: the damping of the recorded benchmarks and accuracy scenes (``benchmarks/results``,
#: ``biafc accuracy``, docs/performance.md): the contact dashpot on, so that those measurements
#: exercise the dashpot kick, and so that the recorded references stay comparable
BENCHMARK_DAMPING = DampingSpec(bending_mode_ratio=2.0e-3, contact_dashpot_ratio=5.0e-3)


def benchmark_chain_spec() -> ChainSpec:
    """The default chain with :data:`BENCHMARK_DAMPING`: the scene of the recorded benchmarks."""
    return default_chain_spec().model_copy(update={"damping": BENCHMARK_DAMPING})
