"""The bench file schema: which instruments, where, and the bench's calibration and limits.

A bench file (YAML) is the one source of truth for a physical (or simulated) bench: addresses,
direction-to-channel map, amplifier gain and piezo limit, generator limits, vibrometer range,
digitiser channels and rate, the stage positions of the cylinders and the soft limits. With
``simulated: true`` the ``simulation:`` section configures the simulated world
(``sim_backend.simbench.SimWorldConfig``). See ``protocols/benches/sim_bench.yaml``.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, ClassVar, Literal, NamedTuple

import numpy as np
from numpy.typing import NDArray
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationInfo,
    field_validator,
    model_validator,
)

from instruments.units import (
    Duration,
    Length,
    PeakToPeakVoltage,
    SampleRate,
    Velocity,
    Voltage,
    format_quantity,
)
from instruments.units import parse_quantity as _pq
from protocols.yamlfile import YamlDoc, load_yaml, parse_yaml, validate

__all__ = ["BenchFile", "BenchSpec", "default_bench_path", "load_bench", "parse_bench"]


class Bound(NamedTuple):
    """The range a bench number must lie in: ``low < value <= high`` (``low <= value`` when
    not ``low_open``), SI; ``dimension`` and ``suffix`` say how the message shows it."""

    low: float
    high: float
    dimension: str
    low_open: bool = True
    suffix: str = ""


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)

    #: field -> the range its value must lie in (SI; checked once its unit is read)
    BOUNDS: ClassVar[dict[str, Bound]] = {}

    @field_validator("*")
    @classmethod
    def _bounded(cls, v: Any, info: ValidationInfo) -> Any:
        bound = cls.BOUNDS.get(info.field_name or "")
        return v if bound is None else _in_range(v, *bound)


#: serial line speed of Zaber ASCII devices and the Polytec OFV-5000 as shipped (baud)
SERIAL_BAUD_DEFAULT = 115200


#: stage positions (soft limits, simulated travel) within this of the origin (m)
TRAVEL_BOUND_M = 5.0


def _in_range(
    value: float, low: float, high: float, dimension: str, low_open: bool = True, suffix: str = ""
) -> float:
    """``value`` if ``low < value <= high`` (``low <= value`` when not ``low_open``), else a
    ``ValueError`` naming the value and the range (the bench file's field and line are added
    by the loader)."""
    ok = math.isfinite(value) and (value > low if low_open else value >= low) and value <= high
    if ok:
        return value

    def show(x: float) -> str:
        return (format_quantity(x, dimension) if dimension else f"{x:g}") + suffix

    above = "above" if low_open else "at least"
    raise ValueError(
        f"{show(value)} is not allowed: give a value {above} {show(low)}, up to {show(high)}"
    )


class GeneratorSpec(_Model):
    """The generator: ``max_amplitude`` (Vpp at its output, at most the 33500B's 20 Vpp into
    high Z), ``sample_rate`` of its arbitrary waveforms (S/s, up to 1 GSa/s)."""

    resource: str
    max_amplitude: PeakToPeakVoltage = 10.0  # Vpp at the output
    sample_rate: SampleRate = 1.0e6
    timeout: Duration = 5.0
    baud_rate: int | None = Field(default=None, gt=0)  # only for a serial (ASRL) resource

    BOUNDS: ClassVar[dict[str, Bound]] = {
        "max_amplitude": Bound(0.0, 20.0, "voltage", suffix="pp"),
        "sample_rate": Bound(0.0, 1e9, "sample_rate"),
        "timeout": Bound(0.0, 600.0, "time"),
    }


class AmplifierSpec(_Model):
    """Power amplifier and piezo: ``gain`` V/V, ``piezo_stroke`` per volt, ``piezo_max`` (V)."""

    gain: float = Field(gt=0)
    piezo_stroke: float  # m/V, written "0.05 um/V"
    piezo_max: Voltage  # largest |V| allowed at the piezo terminals
    kind: Literal["displacement", "force"] = "displacement"
    force_per_volt: float | None = None  # N/V, written "0.5 N/V"

    @field_validator("piezo_stroke", mode="before")
    @classmethod
    def _stroke(cls, v: Any) -> float:
        stroke = _pq(v, "length_per_volt")
        if not (math.isfinite(stroke) and 0 < stroke <= 1e-3):
            raise ValueError(f"{v!r} is not allowed: give a stroke above 0 um/V, up to 1 mm/V")
        return stroke

    @field_validator("force_per_volt", mode="before")
    @classmethod
    def _force(cls, v: Any) -> float | None:
        if v is None:
            return None
        force = _pq(v, "force_per_volt")
        if not (math.isfinite(force) and 0 < force <= 1e6):
            raise ValueError(f"{v!r} is not allowed: give a force above 0 N/V, up to 1 MN/V")
        return force

    BOUNDS: ClassVar[dict[str, Bound]] = {
        "gain": Bound(0.0, 1e4, ""),
        "piezo_max": Bound(0.0, 10e3, "voltage"),
    }


class VibrometerSpec(_Model):
    resource: str
    range: str = "VD-09 10mm/s/V"
    min_signal_level: float = Field(default=0.2, ge=0, le=1)
    #: the controller's signal-level reading on a good target (its full scale); a reading
    #: above it is refused, not clipped
    level_full_scale: float = Field(default=100.0, gt=0, le=1e6)
    timeout: Duration = 2.0
    baud_rate: int = Field(default=SERIAL_BAUD_DEFAULT, gt=0)
    #: RS-232 command table entries that differ on this controller (see instruments.polytec)
    commands: dict[str, str | None] = Field(default_factory=dict)

    @field_validator("commands")
    @classmethod
    def _known_commands(cls, v: dict[str, str | None]) -> dict[str, str | None]:
        from instruments.errors import LimitError
        from instruments.polytec import PolytecSettings

        try:
            PolytecSettings(commands=v)  # the driver's own table refuses an unknown entry
        except LimitError as exc:
            raise ValueError(str(exc).removeprefix("vibrometer commands: ")) from None
        return v

    @field_validator("range")
    @classmethod
    def _known_range(cls, v: str) -> str:
        from instruments.polytec import velocity_range_error

        why = velocity_range_error(v)
        if why is not None:
            raise ValueError(why)
        return v


class StageSpec(_Model):
    """The stage: ``model`` (e.g. ``X-LSM500A``) and/or ``microstep`` (with units, at
    ``resolution`` microsteps per step) say how long a microstep is; checked at connect against
    what the device reports (its id, ``get resolution``, ``get limit.max``)."""

    resource: str
    soft_limits: tuple[Length, Length]
    model: str | None = None
    microstep: Length | None = None
    resolution: int = Field(default=64, gt=0)
    device_id: int | None = None
    speed: Velocity = 0.025
    settle: Duration = 0.2  # wait after each move (the simulated stage settles as long)
    #: the longest wait for one reply of the controller (a move's and homing's own bounds
    #: come from the distance and speed); it was 60 s, which a dead stage cost per reply
    timeout: Duration = 2.0
    baud_rate: int = Field(default=SERIAL_BAUD_DEFAULT, gt=0)

    @field_validator("soft_limits")
    @classmethod
    def _soft_limits(cls, v: tuple[float, float]) -> tuple[float, float]:
        lo, hi = (_in_range(x, -TRAVEL_BOUND_M, TRAVEL_BOUND_M, "length", low_open=False)
                  for x in v)  # fmt: skip
        return lo, hi

    BOUNDS: ClassVar[dict[str, Bound]] = {
        "speed": Bound(0.0, 1.0, "velocity"),
        "settle": Bound(0.0, 60.0, "time", low_open=False),
        "timeout": Bound(0.0, 3600.0, "time"),
    }

    @model_validator(mode="after")
    def _order(self) -> StageSpec:
        if not self.soft_limits[0] < self.soft_limits[1]:
            raise ValueError("soft_limits must be [low, high] with low < high")
        if self.model is None and self.microstep is None:
            raise ValueError(
                "name the stage 'model' (e.g. X-LSM500A) or its 'microstep' (e.g. 0.047625 um)"
            )
        if self.microstep is not None and not self.microstep > 0:
            raise ValueError("microstep must be > 0")
        top = self.max_speed()
        if top is not None and self.speed > top * (1 + 1e-9):
            raise ValueError(
                f"speed: {self.speed * 1e3:.4g} mm/s is above this stage's "
                f"{top * 1e3:.4g} mm/s (10,000 full steps/s, Zaber's protocol manual); the "
                "stage refuses it at connect"
            )
        return self

    def max_speed(self) -> float | None:
        """The stage's top speed (m/s) from its microstep (given, or its model's), None when
        neither is known (:func:`instruments.zaber.max_speed_m_per_s`)."""
        from instruments.errors import LimitError
        from instruments.zaber import max_speed_m_per_s, microstep_of_model

        micro = self.microstep
        if micro is None and self.model is not None:
            try:
                micro = microstep_of_model(self.model, self.resolution)[0]
            except LimitError:
                return None
        return None if micro is None else max_speed_m_per_s(micro, self.resolution)


class DaqSpec(_Model):
    """The digitiser: NI device, channels, trigger terminal, ``max_rate`` (the highest sample
    rate per channel this bench allows) and ``terminal_config`` of both inputs (``RSE``,
    ``NRSE``, ``differential``, ``pseudodifferential``, or ``default``: the device's own)."""

    device: str = "Dev1"
    velocity_channel: str = "Dev1/ai0"
    reference_channel: str = "Dev1/ai1"
    trigger: str = "/Dev1/PFI0"
    max_rate: SampleRate = 2.0e6
    terminal_config: Literal["default", "RSE", "NRSE", "differential", "pseudodifferential"] = (
        "default"
    )
    velocity_range: Voltage = 10.0
    reference_range: Voltage = 10.0

    BOUNDS: ClassVar[dict[str, Bound]] = {
        "max_rate": Bound(0.0, 100e6, "sample_rate"),
        "velocity_range": Bound(0.0, 100.0, "voltage"),
        "reference_range": Bound(0.0, 100.0, "voltage"),
    }

    @model_validator(mode="after")
    def _channels_on_the_device(self) -> DaqSpec:
        """Both inputs on ``device`` (whose rate ceiling and lock they use) and apart: on the NI
        path a typo (``Dev2/ai0`` beside ``device: Dev1``) failed only at the first record, its
        error naming the field that was right (a second reader; the simulated digitiser refused
        it)."""
        dev = self.device.strip().lower()
        for name, channel in (
            ("velocity_channel", self.velocity_channel),
            ("reference_channel", self.reference_channel),
        ):
            if channel.strip().lstrip("/").lower().partition("/")[0] != dev:
                raise ValueError(f"{name}: {channel!r} is not on daq.device {self.device!r}")
        if self.velocity_channel.strip().lower() == self.reference_channel.strip().lower():
            raise ValueError(
                f"reference_channel: {self.reference_channel!r} is the velocity channel too; "
                "give each input its own"
            )
        return self  # the trigger may be routed from another device (RTSI, PXI): not checked


class PositionGrid(_Model):
    first: Length
    pitch: Length
    count: int = Field(ge=1, le=1000, strict=True)

    @field_validator("pitch")
    @classmethod
    def _pitch(cls, v: float) -> float:
        if v == 0:
            raise ValueError("0 m puts every cylinder at one place; give the spacing")
        return v


class SimulationSpec(_Model):
    """Maps onto ``SimWorldConfig`` (see there for the meaning of each field)."""

    seed: int = Field(default=0, ge=0)
    speedup: float = Field(default=0.0, ge=0)
    spot_tolerance: Length = 2.0e-3
    stage_travel: tuple[Length, Length] = (0.0, 0.5)
    vibrometer_full_scale: Voltage = 10.0
    vibrometer_noise: Velocity = 2.0e-6
    digitiser_noise: Voltage = 3.0e-4
    adc_bits: int = Field(default=16, ge=1, le=32)
    dem_duration: Duration = 30.0e-3
    dem_integrator: str = "default"
    #: the most MB of DEM runs the simulated bench keeps (None: its default, 512)
    dem_cache_MB: float | None = Field(default=None, gt=0, le=1e6)
    faults: dict[str, Any] = Field(default_factory=dict)

    BOUNDS: ClassVar[dict[str, Bound]] = {
        "speedup": Bound(0.0, 1.0e6, "", low_open=False),
        "spot_tolerance": Bound(0.0, 0.1, "length"),
        "vibrometer_full_scale": Bound(0.0, 100.0, "voltage"),
        "vibrometer_noise": Bound(0.0, 10.0, "velocity", low_open=False),
        "digitiser_noise": Bound(0.0, 10.0, "voltage", low_open=False),
        "dem_duration": Bound(0.0, 10.0, "time"),
    }

    @field_validator("stage_travel")
    @classmethod
    def _stage_travel(cls, v: tuple[float, float]) -> tuple[float, float]:
        lo, hi = (_in_range(x, -TRAVEL_BOUND_M, TRAVEL_BOUND_M, "length", low_open=False)
                  for x in v)  # fmt: skip
        if not lo < hi:
            raise ValueError("give [low, high] with low < high")
        return lo, hi


class BenchSpec(_Model):
    """A validated bench file (SI floats)."""

    name: str
    simulated: bool = False
    #: the VISA library for VISA resources: "@py" pyvisa-py (shipped), "@ivi" the NI-VISA or
    #: Keysight IO Libraries installed on the PC (their USB and GPIB drivers)
    visa_backend: Literal["@py", "@ivi"] = "@py"
    chain: str | None = None  # chain file (sim_backend.dem) relative to the bench file
    # KEY=VALUE settings applied to that chain (``diameter=12mm``), validated like the chain file
    chain_set: list[str] = Field(default_factory=list)
    generator: GeneratorSpec
    direction_channel: dict[Literal["ltr", "rtl"], Literal[1, 2]]
    amplifier: AmplifierSpec
    vibrometer: VibrometerSpec
    stage: StageSpec
    daq: DaqSpec = Field(default_factory=DaqSpec)
    cylinder_positions: list[Length] | PositionGrid
    simulation: SimulationSpec | None = None

    @field_validator("name")
    @classmethod
    def _one_line_name(cls, v: str) -> str:
        if not v.strip() or len(v) > 200 or any(ord(c) < 32 or ord(c) == 127 for c in v):
            raise ValueError(f"{v[:60]!r}: one line of up to 200 characters, no control characters")
        return v

    @field_validator("cylinder_positions")
    @classmethod
    def _some_positions(cls, v: Any) -> Any:
        if isinstance(v, list) and not 1 <= len(v) <= 1000:
            raise ValueError(f"{len(v)} positions; give 1 to 1000")
        if isinstance(v, list) and len(v) > 1:  # as a pitch of 0 is refused
            x = np.asarray(v, dtype=np.float64)
            order = np.argsort(x, kind="stable")
            same = np.abs(np.diff(x[order])) < 1e-9  # neighbours once sorted
            if same.any():
                k = int(np.argmax(same))
                j, i = sorted((int(order[k]), int(order[k + 1])))
                raise ValueError(
                    f"cylinders {j + 1} and {i + 1} are both at {x[i] * 1e3:.4g} mm; give each "
                    "cylinder its own position"
                )
        return v

    @model_validator(mode="after")
    def _check(self) -> BenchSpec:
        if set(self.direction_channel) != {"ltr", "rtl"}:
            raise ValueError("direction_channel: map both ltr and rtl to a generator channel")
        if self.direction_channel["ltr"] == self.direction_channel["rtl"]:
            raise ValueError("direction_channel: ltr and rtl need different channels")
        low, high = self.stage.soft_limits
        for i, p in enumerate(self.positions_m()):
            if not low <= p <= high:
                raise ValueError(
                    f"cylinder_positions: cylinder {i + 1} at {p * 1e3:.4g} mm is outside the "
                    f"stage soft limits {low * 1e3:.4g}..{high * 1e3:.4g} mm"
                )
        if self.simulated and self.simulation is None:
            object.__setattr__(self, "simulation", SimulationSpec())
        if self.simulated and self.simulation is not None:
            t_lo, t_hi = self.simulation.stage_travel
            if low < t_lo or high > t_hi:
                raise ValueError(
                    f"stage.soft_limits: {low * 1e3:.4g}..{high * 1e3:.4g} mm reach beyond the "
                    f"simulated stage's travel {t_lo * 1e3:.4g}..{t_hi * 1e3:.4g} mm "
                    "(simulation.stage_travel)"
                )
        return self

    def positions_m(self) -> NDArray[np.float64]:
        """``[N]`` stage position (m) of each cylinder, cylinder order."""
        cp = self.cylinder_positions
        if isinstance(cp, PositionGrid):
            return cp.first + cp.pitch * np.arange(cp.count, dtype=np.float64)
        return np.asarray(cp, dtype=np.float64)

    @property
    def n_cylinders(self) -> int:
        return int(self.positions_m().shape[0])

    @property
    def generator_V_per_m(self) -> float:
        """Generator peak volts per metre of actuator displacement (the calibration)."""
        return 1.0 / (self.amplifier.gain * self.amplifier.piezo_stroke)

    def generator_Vpp(self, amplitude: float, kind: str) -> float:
        """Generator Vpp for a protocol amplitude of ``kind`` (generator_Vpp or displacement_m)."""
        if kind == "generator_Vpp":
            return amplitude
        return 2.0 * amplitude * self.generator_V_per_m

    def amplitude_limit_error(self, vpp: float, peak_factor: float = 1.0) -> str | None:
        """Why ``vpp`` (generator Vpp) is not allowed on this bench, or ``None``;
        ``peak_factor``: the waveform's ``instruments.keysight.arb_peak_factor`` (its peak at
        the piezo is taken as ``vpp / 2 x peak_factor x gain``, as the driver checks it)."""
        from instruments.keysight import GeneratorLimits, unequal_peaks

        if not math.isfinite(vpp) or vpp <= 0:
            return f"{vpp!r} Vpp is not a positive amplitude"
        vpp_min = GeneratorLimits.min_amplitude_Vpp  # the driver's, the class default
        if vpp < vpp_min * (1 - 1e-12):
            return f"{vpp:.4g} Vpp is below the generator minimum {vpp_min:.4g} Vpp"
        if vpp > self.generator.max_amplitude * (1 + 1e-12):
            return (
                f"{vpp:.4g} Vpp is above the generator limit {self.generator.max_amplitude:.4g} Vpp"
            )
        piezo_V = 0.5 * vpp * peak_factor * self.amplifier.gain
        if piezo_V > self.amplifier.piezo_max * (1 + 1e-12):
            unequal = unequal_peaks(peak_factor)
            return (
                f"{vpp:.4g} Vpp gives up to {piezo_V:.4g} V at the piezo, above its limit "
                f"{self.amplifier.piezo_max:.4g} V" + (f" ({unequal})" if unequal else "")
            )
        return None


class BenchFile:
    """A bench with its source text, its path and its line map."""

    def __init__(self, bench: BenchSpec, doc: YamlDoc, path: Path | None) -> None:
        self.bench = bench
        self.doc = doc
        self.path = path

    @property
    def text(self) -> str:
        return self.doc.text

    def chain_path(self) -> Path | None:
        if self.bench.chain is None:
            return None
        p = Path(self.bench.chain)
        if not p.is_absolute() and self.path is not None:
            p = self.path.parent / p
        return p


def default_bench_path() -> Path:
    """The shipped simulated bench, ``protocols/benches/sim_bench.yaml``."""
    return Path(__file__).resolve().parent / "benches" / "sim_bench.yaml"


def load_bench(
    path: str | Path | None = None, chain_set: list[str] | tuple[str, ...] = ()
) -> BenchFile:
    """Load and validate a bench file (default: the shipped simulated bench).

    ``chain_set`` (``run_protocol --set KEY=VALUE``) adds chain settings to the file's
    ``chain_set``; they become part of the bench text, so the run file records them."""
    p = Path(path) if path is not None else default_bench_path()
    doc = load_yaml(p)
    _not_a_protocol(doc)
    if chain_set:
        import yaml

        items = [*list(validate(doc, BenchSpec).chain_set), *chain_set]
        text = _without_key(doc.text, "chain_set")
        text = text.rstrip("\n") + "\n# run_protocol --set\n"
        text += yaml.safe_dump({"chain_set": items}, default_flow_style=None, width=1000)
        doc = parse_yaml(text, str(p))
    return BenchFile(validate(doc, BenchSpec), doc, p)


def _without_key(text: str, key: str) -> str:
    """``text`` without a top-level ``key:`` line (and its indented continuation lines)."""
    out: list[str] = []
    skipping = False
    for line in text.splitlines():
        if line.startswith(f"{key}:"):
            skipping = True
            continue
        if skipping and (line.startswith((" ", "\t", "-")) or not line.strip()):
            continue
        skipping = False
        out.append(line)
    return "\n".join(out) + "\n"


def _not_a_protocol(doc: YamlDoc) -> None:
    """A protocol given where a bench file belongs, said as such (it read "unknown key
    'directions'; did you mean 'direction_channel'?")."""
    data = doc.data
    if isinstance(data, dict) and {"directions", "burst"} <= set(data) and "generator" not in data:
        raise doc.error(
            (),
            "this is a protocol (it has directions and burst), not a bench file: give it as "
            "the protocol (run_protocol PROTOCOL.yaml --bench BENCH.yaml)",
        )


def parse_bench(text: str, source: str = "<bench>") -> BenchFile:
    doc = parse_yaml(text, source)
    _not_a_protocol(doc)
    return BenchFile(validate(doc, BenchSpec), doc, None)
