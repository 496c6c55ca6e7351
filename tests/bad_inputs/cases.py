"""The bad inputs every command must refuse up front (issue 16): a table of cases.

Each :class:`Case` names the files it writes into a scratch folder, the command line a person
would type there (``run_protocol ...`` or ``biafc ...``) and fragments of the one line it must
print on stderr. The runner (``test_cases.py``) asserts for every case: exit 2, exactly one line
on stderr, no traceback, nothing written, no instrument opened, under 2 s and 500 MB.

A case whose fix has not landed yet carries ``pending`` (the reason): it runs as
``xfail(strict=True)``, so it turns into a failure to un-mark the day it passes.

docs/reliability.md holds this table with the outcomes (``python -m tests.bad_inputs.doc_table``
rewrites it; ``test_doc_table.py`` checks it is current).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
SMOKE = (REPO / "protocols" / "smoke.yaml").read_text(encoding="utf-8")
SIM_BENCH = (REPO / "protocols" / "benches" / "sim_bench.yaml").read_text(encoding="utf-8")

#: named byte strings the cases may be built from (see ``sources`` in conftest.py):
#: ``run_file``, a complete run file; ``other_hdf5``, an HDF5 file that is not a run file
Sources = Mapping[str, bytes]
Content = str | bytes | Callable[[Sources], bytes]

PENDING_LAYER = "issue 16: validation layer (i16-request)"
PENDING_BOUNDS = "issue 16: bounded inputs (i16-bounds)"


@dataclass(frozen=True)
class Case:
    """One bad input: ``name`` (a test id), ``what`` (for the docs table), the ``files`` it
    writes (name -> text, bytes, or a function of the sources), the command line ``argv``
    (program first) and the ``expect``\\ ed fragments of the one line on stderr."""

    name: str
    what: str
    argv: tuple[str, ...]
    expect: tuple[str, ...]
    files: Mapping[str, Content] = field(default_factory=dict)
    pending: str | None = None


def _replace(text: str, old: str, new: str) -> str:
    if old not in text:
        raise ValueError(f"{old!r} is not in the template")
    return text.replace(old, new, 1)


def proto(old: str, new: str) -> str:
    """The smoke protocol with ``old`` replaced by ``new``."""
    return _replace(SMOKE, old, new)


def bench(old: str, new: str) -> str:
    """The simulated bench with ``old`` replaced by ``new``."""
    return _replace(SIM_BENCH, old, new)


def head(
    source: str, n: int | None = None, fraction: float | None = None
) -> Callable[[Sources], bytes]:
    """The first ``n`` bytes (or ``fraction``) of the source ``source``."""

    def make(sources: Sources) -> bytes:
        data = sources[source]
        k = n if n is not None else int(len(data) * (fraction or 0.0))
        return data[:k]

    return make


def damaged(name: str, start: int, stop: int) -> Callable[[Sources], bytes]:
    """The source ``name`` with bytes ``start:stop`` overwritten (its length unchanged)."""

    def make(sources: Sources) -> bytes:
        data = bytearray(sources[name])
        data[start:stop] = b"\xaa" * (stop - start)
        return bytes(data)

    return make


def source(name: str) -> Callable[[Sources], bytes]:
    return lambda sources: sources[name]


GARBAGE = bytes((i * 151 + 89) % 256 for i in range(4096))  # not UTF-8 from byte 1 on
DEEP = "a: " + "[" * 5000 + "]" * 5000 + "\n"
LAUGHS = "a0: &a0 [lol, lol, lol, lol, lol, lol, lol, lol, lol]\n" + "".join(
    f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 9)}]\n" for i in range(1, 10)
)
FLOW_LAUGHS = (
    "{a0: &a0 [l, l, l, l, l, l, l, l, l], "
    + ", ".join(f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 9)}]" for i in range(1, 10))
    + "}"
)
BIG = SMOKE + ("#" + " padding" * 12 + "\n") * 12_000  # about 1.2 MB of comments

RUN = ("run_protocol", "proto.yaml", "--out", "run.h5")
RUN_BENCH = ("run_protocol", "proto.yaml", "--bench", "bench.yaml", "--out", "run.h5")
SIMULATE = ("biafc", "simulate", "--direction", "ltr", "--amplitude", "1 um", "--out", "sim.h5")


def _p(name: str, what: str, old: str, new: str, expect: tuple[str, ...], **kw: str) -> Case:
    return Case(name, what, RUN, expect, {"proto.yaml": proto(old, new)}, **kw)  # type: ignore[arg-type]


def _b(name: str, what: str, old: str, new: str, expect: tuple[str, ...], **kw: str) -> Case:
    files = {"proto.yaml": SMOKE, "bench.yaml": bench(old, new)}
    return Case(name, what, RUN_BENCH, expect, files, **kw)  # type: ignore[arg-type]


CASES: tuple[Case, ...] = (
    # -- the files themselves: bytes, size, nesting, aliases ---------------------------------
    Case("protocol_binary", "protocol file of binary garbage", RUN,
         ("proto.yaml", "not a text file"), {"proto.yaml": GARBAGE}),
    Case("bench_binary", "bench file of binary garbage", RUN_BENCH,
         ("bench.yaml", "not a text file"), {"proto.yaml": SMOKE, "bench.yaml": GARBAGE}),
    Case("protocol_nul", "protocol with a NUL byte", RUN, ("proto.yaml",),
         {"proto.yaml": SMOKE.replace("name: smoke", "name: sm\x00oke")}),
    Case("protocol_too_big", "protocol of 1.2 MB (comments)", RUN,
         ("proto.yaml", "1 MiB"), {"proto.yaml": BIG}),
    Case("protocol_deep", "protocol nested 5000 deep", RUN,
         ("proto.yaml", "deeper than"), {"proto.yaml": DEEP}),
    Case("protocol_laughs", 'protocol "billion laughs" (aliases 9 x 9 ... deep)', RUN,
         ("proto.yaml", "aliases"), {"proto.yaml": LAUGHS}),
    Case("protocol_merge", "protocol with a merge key (<<)", RUN, ("proto.yaml", "<<"),
         {"proto.yaml": "base: &b {name: x}\n<<: *b\n" + SMOKE.split("\n", 2)[2]}),
    Case("protocol_recursive_alias", "protocol with a self-referencing alias", RUN,
         ("proto.yaml",), {"proto.yaml": SMOKE + "extra: &x [*x]\n"}),
    Case("protocol_list_key", "protocol with a list as a key", RUN, ("proto.yaml",),
         {"proto.yaml": SMOKE + "? [1, 2]\n: x\n"}),
    Case("protocol_empty", "empty protocol file", RUN, ("proto.yaml",), {"proto.yaml": ""}),
    Case("protocol_list", "protocol that is a list, not a mapping", RUN,
         ("proto.yaml", "mapping"), {"proto.yaml": "- 1\n- 2\n"}),
    Case("protocol_missing", "protocol file that does not exist", ("run_protocol",
         "nothere.yaml", "--out", "run.h5"), ("nothere",)),
    Case("chain_binary", "chain file of binary garbage (biafc simulate --chain)",
         (*SIMULATE, "--chain", "chain.yaml"), ("chain.yaml", "not a text file"),
         {"chain.yaml": GARBAGE}),
    Case("chain_deep", "chain file nested 5000 deep", (*SIMULATE, "--chain", "chain.yaml"),
         ("chain.yaml", "deeper than"), {"chain.yaml": DEEP}),
    Case("chain_laughs", 'chain file "billion laughs"', (*SIMULATE, "--chain", "chain.yaml"),
         ("chain.yaml", "aliases"), {"chain.yaml": LAUGHS}),
    Case("study_binary", "study file of binary garbage (biafc study)",
         ("biafc", "study", "study.yaml", "--out", "study.h5"), ("study.yaml", "not a text file"),
         {"study.yaml": GARBAGE}),
    Case("study_laughs", 'study file "billion laughs"',
         ("biafc", "study", "study.yaml", "--out", "study.h5"), ("study.yaml", "aliases"),
         {"study.yaml": LAUGHS}),
    Case("set_laughs", 'biafc simulate --set with a "billion laughs" value',
         (*SIMULATE, "--set", f"lengths={FLOW_LAUGHS}"), ("--set", "aliases")),
    # -- run files: biafc figures, --resume ----------------------------------------------------
    Case("figures_1kB", "biafc figures on the first 1 kB of a run file",
         ("biafc", "figures", "cut.h5", "--out", "figs"), ("cut.h5", "truncated"),
         {"cut.h5": head("run_file", n=1024)}),
    Case("figures_half", "biafc figures on half a run file",
         ("biafc", "figures", "cut.h5", "--out", "figs"), ("cut.h5", "truncated"),
         {"cut.h5": head("run_file", fraction=0.5)}),
    Case("figures_damaged", "biafc figures on a run file with bytes 100-600 overwritten",
         ("biafc", "figures", "bad.h5", "--out", "figs"), ("bad.h5", "damaged"),
         {"bad.h5": damaged("run_file", 100, 600)}),
    Case("figures_text", "biafc figures on a text file",
         ("biafc", "figures", "notes.h5", "--out", "figs"), ("notes.h5", "not an HDF5 file"),
         {"notes.h5": "a text file\n"}),
    Case("figures_empty", "biafc figures on an empty file",
         ("biafc", "figures", "empty.h5", "--out", "figs"), ("empty.h5", "empty file"),
         {"empty.h5": b""}),
    Case("figures_folder", "biafc figures on a folder", ("biafc", "figures", "."),
         ("folder",)),
    Case("figures_other_hdf5", "biafc figures on an HDF5 file that is not a run file",
         ("biafc", "figures", "other.h5", "--out", "figs"), ("other.h5", "not a biafc run"),
         {"other.h5": source("other_hdf5")}),
    Case("resume_text", "--resume of a text file", ("run_protocol", "--resume", "notes.h5"),
         ("notes.h5", "not an HDF5 file"), {"notes.h5": "a text file\n"}),
    Case("resume_1kB", "--resume of the first 1 kB of a run file",
         ("run_protocol", "--resume", "cut.h5"), ("cut.h5", "truncated"),
         {"cut.h5": head("run_file", n=1024)}),
    Case("resume_half_with_protocol", "--resume of half a run file, protocol given",
         ("run_protocol", "proto.yaml", "--resume", "cut.h5"), ("cut.h5", "truncated"),
         {"proto.yaml": SMOKE, "cut.h5": head("run_file", fraction=0.5)}),
    Case("resume_damaged", "--resume of a run file with bytes 100-600 overwritten",
         ("run_protocol", "--resume", "bad.h5"), ("bad.h5", "damaged"),
         {"bad.h5": damaged("run_file", 100, 600)}),
    Case("out_existing_truncated", "--out naming the first 1 kB of a run file",
         ("run_protocol", "proto.yaml", "--out", "cut.h5"), ("cut.h5", "not a run file"),
         {"proto.yaml": SMOKE, "cut.h5": head("run_file", n=1024)}),
    Case("resume_folder", "--resume .", ("run_protocol", "--resume", "."),
         ("is a folder", "run file")),
    Case("resume_complete", "--resume of a complete run file",
         ("run_protocol", "--resume", "done.h5"), ("done.h5", "complete"),
         {"done.h5": source("run_file")}),
    Case("resume_other_hdf5", "--resume of an HDF5 file that is not a run file",
         ("run_protocol", "--resume", "other.h5"), ("other.h5", "not a biafc run"),
         {"other.h5": source("other_hdf5")}),
    # -- biafc simulate -------------------------------------------------------------------------
    Case("simulate_dt_50us", "biafc simulate --dt '50 us' (unstable)",
         (*SIMULATE, "--dt", "50 us"), ("--dt", "stability limit")),
    Case("simulate_dt_1s", "biafc simulate --dt '1 s'", (*SIMULATE, "--dt", "1 s"),
         ("--dt", "stability limit")),
    Case("simulate_dt_coarse", "biafc simulate --dt '5 us' (stable, coarser than a sample)",
         (*SIMULATE, "--dt", "5 us"), ("--dt", "record period")),
    Case("simulate_negative_amplitude", "biafc simulate --amplitude -2um",
         ("biafc", "simulate", "--direction", "ltr", "--amplitude", "-2um", "--out", "sim.h5"),
         ("--amplitude: must be > 0",)),
    Case("simulate_duration_100s", "biafc simulate --duration 100s (24 GB: out of memory)",
         (*SIMULATE, "--duration", "100s"), ("--duration: 100 s is outside 10 us .. 10 s",)),
    Case("simulate_duration_10s", "biafc simulate --duration 10s (1.2 GiB of output)",
         (*SIMULATE, "--duration", "10s"), ("--duration", "above the bound of 1 GiB")),
    Case("simulate_frequency_0", "biafc simulate --frequency 0kHz",
         (*SIMULATE, "--frequency", "0kHz"), ("--frequency: 0 Hz is outside 1 Hz .. 10 MHz",)),
    Case("simulate_frequency_nyquist", "biafc simulate --frequency 1MHz at 500 kS/s",
         (*SIMULATE, "--frequency", "1MHz"), ("--frequency", "Nyquist frequency 250 kHz")),
    Case("simulate_sigma_f_wide", "biafc simulate --sigma-f 20kHz (wider than 8.92 kHz)",
         (*SIMULATE, "--sigma-f", "20kHz"), ("--sigma-f", "not below its centre frequency")),
    Case("simulate_cycles_100000", "biafc simulate --cycles 100000",
         (*SIMULATE, "--cycles", "100000"), ("--cycles: 100000 is outside 1 .. 1000",)),
    Case("accuracy_rate_below_nyquist", "biafc accuracy --rate 2kS/s (the burst aliases)",
         ("biafc", "accuracy", "--scene", "linear", "--rate", "2kS/s"),
         ("--rate: the 8.92 kHz burst", "Nyquist frequency 1 kHz")),
    Case("accuracy_too_large", "biafc accuracy --duration 10s --rate 1MS/s (2.4 GiB)",
         ("biafc", "accuracy", "--duration", "10s", "--rate", "1MS/s"),
         ("--duration", "above the bound of 1 GiB")),
    Case("repair_a_folder", "biafc repair on a folder", ("biafc", "repair", "adir"),
         ("adir is a folder; give a run file",), {"adir/keep.txt": "x"}),
    Case("simulate_out_a_folder", "biafc simulate --out a folder",
         ("biafc", "simulate", "--direction", "ltr", "--amplitude", "1 um", "--out", "adir"),
         ("--out: adir is a folder",), {"adir/keep.txt": "x"}),
    Case("bands_csv_a_folder", "biafc bands --csv a folder", ("biafc", "bands", "--csv", "adir"),
         ("--csv: adir is a folder; give a file name",), {"adir/keep.txt": "x"}),
    Case("figures_out_a_file", "biafc figures RUN.h5 --out a file", ("biafc", "figures",
         "run.h5", "--out", "afile"), ("--out: afile is a file",),
         {"run.h5": source("run_file"), "afile": "x"}),
    Case("compare_out_a_file", "biafc compare RUN.h5 --out a file", ("biafc", "compare",
         "run.h5", "--out", "afile"), ("--out: afile is a file",),
         {"run.h5": source("run_file"), "afile": "x"}),
    Case("regime_out_a_file", "biafc regime --out a file", ("biafc", "regime", "--out",
         "afile"), ("--out: afile is a file",), {"afile": "x"}),
    _p("amplitude_twice", "an amplitude listed twice (0.5 um and 500 nm)",
       "amplitudes: [0.5 um, 3 um]", "amplitudes: [0.5 um, 3 um, 500 nm]",
       ("proto.yaml:6: amplitudes: amplitude 3 (500 nm) is amplitude 1 (0.5 um) again",)),
    _p("cylinder_twice_named", "a cylinder listed twice is named",
       "cylinders: [1, 8, 16]", "cylinders: [1, 8, 8]",
       ("cylinders: cylinder 8 is listed twice",)),
    Case("protocol_is_a_bench", "a bench file given as the protocol",
         ("run_protocol", "bench.yaml", "--out", "run.h5"),
         ("bench.yaml", "this is a bench file", "give it as --bench"), {"bench.yaml": SIM_BENCH}),
    Case("bench_is_a_protocol", "a protocol given as the bench file", RUN_BENCH,
         ("bench.yaml", "this is a protocol", "not a bench file"),
         {"proto.yaml": SMOKE, "bench.yaml": SMOKE}),
    _p("amplitude_range_equal", "a range whose start and stop are the same",
       "amplitudes: [0.5 um, 3 um]", "amplitudes: {start: 1 um, stop: 1 um, count: 3}",
       ("amplitudes: start and stop are the same",)),
    _p("duplicate_key", "a key given twice (averages on lines 8 and 9)", "averages: 2",
       "averages: 2\naverages: 3",
       ("proto.yaml:9: duplicate key 'averages' (first given on line 8)",)),
    _p("duplicate_nested_key", "a key given twice inside burst.ltr", "shape: narrowband",
       "shape: narrowband, f_center: 9 kHz",
       ("proto.yaml:5: duplicate key 'f_center' in burst.ltr (first given on line 5)",)),
    # -- protocol fields (the validation layer) ---------------------------------------------
    _p("cylinders_empty", "cylinders: []", "cylinders: [1, 8, 16]", "cylinders: []",
       ("proto.yaml", "cylinders")),
    _p("cycles_inf", "burst cycles: .inf", "shape: narrowband", "cycles: .inf",
       ("proto.yaml", "cycles")),
    _p("cycles_tiny", "burst cycles: 1e-9", "shape: narrowband", "cycles: 1e-9",
       ("proto.yaml", "cycles")),
    _p("duration_1h", "acquisition duration: 1 h", "duration: 10 ms", "duration: 1 h",
       ("proto.yaml", "duration")),
    _p("duration_10Ms", "acquisition duration: 10 Ms", "duration: 10 ms", "duration: 10 Ms",
       ("proto.yaml", "duration")),
    _p("above_nyquist", "900 kHz burst recorded at 200 kS/s", "f_center: 8.92 kHz",
       "f_center: 900 kHz", ("proto.yaml", "Nyquist")),
    _p("timeout_1ns", "acquisition timeout: 1 ns", "pre_trigger: 0.5 ms",
       "pre_trigger: 0.5 ms, timeout: 1 ns", ("proto.yaml", "timeout")),
    _p("averages_true", "averages: true", "averages: 2", "averages: true",
       ("proto.yaml", "averages")),
    _p("max_failed_negative", "max_failed_in_a_row: -1", "retries: 2",
       "retries: 2\nmax_failed_in_a_row: -1", ("proto.yaml", "max_failed_in_a_row", "0 to")),
    _p("name_newline", "a line break in the name", "name: smoke", 'name: "a\\nb"',
       ("proto.yaml", "name")),
    _p("pattern_attribute", "output pattern with attribute access",
       'output: "runs/{name}_{timestamp}.h5"', 'output: "{name.__class__}.h5"',
       ("proto.yaml", "output")),
    _p("unknown_key", "an unknown key", "settle: 10 ms", "settle: 10 ms\nsetle: 5 ms",
       ("proto.yaml", "unknown key")),
    _p("wrong_unit", "settle: 10 kg", "settle: 10 ms", "settle: 10 kg",
       ("proto.yaml", "settle")),
    Case("out_proc", "--out /proc/x.h5", ("run_protocol", "proto.yaml", "--out", "/proc/x.h5"),
         ("/proc/x.h5",), {"proto.yaml": SMOKE}),
    Case("out_not_h5", "--out run.log (before: the run's log took the name, exit 1; 'ltr.a' and "
         "'ltr.b' shared ltr.log)", ("run_protocol", "proto.yaml", "--out", "run.log"),
         ("--out", "run.log", "ends in .h5"), {"proto.yaml": SMOKE}),
    _p("pattern_not_h5", "output pattern not ending in .h5", 'output: "runs/{name}_{timestamp}.h5"',
       'output: "runs/{name}_{timestamp}"', ("proto.yaml", "output", "must end in .h5")),
    # -- bench fields (the validation layer) -------------------------------------------------
    _b("velocity_range_0", "daq velocity_range: 0 V", "velocity_range: 10 V",
       "velocity_range: 0 V", ("bench.yaml", "velocity_range")),
    _b("sample_rate_0", "generator sample_rate: 0", "sample_rate: 1 MSa/s", "sample_rate: 0",
       ("bench.yaml", "sample_rate")),
    _b("piezo_stroke_0", "piezo_stroke: 0 um/V", "piezo_stroke: 0.05 um/V",
       "piezo_stroke: 0 um/V", ("bench.yaml", "piezo_stroke")),
    _b("piezo_stroke_negative", "piezo_stroke: -0.05 um/V", "piezo_stroke: 0.05 um/V",
       "piezo_stroke: -0.05 um/V", ("bench.yaml", "piezo_stroke")),
    _b("max_amplitude_negative", "generator max_amplitude: -10 Vpp", "max_amplitude: 10 Vpp",
       "max_amplitude: -10 Vpp", ("bench.yaml", "max_amplitude")),
    _b("stage_speed_0", "stage speed: 0 mm/s", "speed: 25 mm/s", "speed: 0 mm/s",
       ("bench.yaml", "speed")),
    _b("vibrometer_range", "vibrometer range VD-09 5000mm/s/V", "range: VD-09 50mm/s/V",
       "range: VD-09 5000mm/s/V",
       ("bench.yaml", "range", "5, 10, 20, 50, 100, 200, 500, 1000 mm/s/V")),
    _b("sim_integrator", "simulation dem_integrator: bogus (before: --dry-run passed, the run "
       "wrote a failed file)", "dem_duration: 30 ms",
       "dem_duration: 30 ms\n  dem_integrator: bogus",
       ("bench.yaml", "simulation.dem_integrator", "unknown integrator 'bogus'", "blanes-moan4")),
    _b("sim_fault_typo", "an unknown fault name (before: passed --dry-run, refused at connect)",
       "faults: {}", "faults: {trigger_cabel: true}",
       ("bench.yaml", "simulation.faults", "trigger_cabel", "digitiser_timeout")),
    _b("vibrometer_command_typo", "an unknown vibrometer command entry (before: passed "
       "--dry-run, refused at connect without a line)", "min_signal_level: 0.2",
       'min_signal_level: 0.2\n  commands: {signal_levle_get: "Get,SignalLevel,0,Value"}',
       ("bench.yaml", "vibrometer.commands", "signal_levle_get", "signal_level_get")),
    _b("dem_cache_MB_0", "simulation dem_cache_MB: 0", "dem_duration: 30 ms",
       "dem_duration: 30 ms\n  dem_cache_MB: 0", ("bench.yaml", "dem_cache_MB")),
    Case("study_integrator", "study simulation integrator: bogus (before: every cell failed, "
         "exit 4)", ("biafc", "study", "study.yaml", "--out", "study.h5"),
         ("study.yaml", "simulation.integrator", "unknown integrator 'bogus'"),
         {"study.yaml": (REPO / "protocols" / "studies" / "example.yaml").read_text(
             encoding="utf-8").replace("rate: 200 kS/s}", "rate: 200 kS/s, integrator: bogus}")}),
    _b("visa_backend", 'visa_backend: "@ni" (not a VISA library the bench knows)',
       "simulated: true", 'simulated: true\nvisa_backend: "@ni"', ("bench.yaml", "visa_backend")),
    _b("level_full_scale_0", "vibrometer level_full_scale: 0", "min_signal_level: 0.2",
       "min_signal_level: 0.2\n  level_full_scale: 0", ("bench.yaml", "level_full_scale")),
    _b("sample_rate_0_unit", "generator sample_rate: 0 Sa/s", "sample_rate: 1 MSa/s",
       "sample_rate: 0 Sa/s", ("bench.yaml", "generator.sample_rate")),
    _b("bench_positions_beyond_chain", "40 cylinder positions on a simulated 31-cylinder chain",
       "pitch: 13.6 mm, count: 31}", "pitch: 10 mm, count: 40}",
       ("bench.yaml:39: cylinder_positions", "the simulated chain has 31 cylinders")),
    _b("soft_limits_beyond_travel", "stage soft limits beyond the simulated stage's travel",
       "soft_limits: [0 mm, 480 mm]", "soft_limits: [0 mm, 800 mm]",
       ("bench.yaml:27: stage.soft_limits", "beyond the simulated stage's travel 0..500 mm")),
    _b("stage_speed_above_top", "stage speed above the X-LSM's 10,000 full steps/s",
       "speed: 25 mm/s", "speed: 40 mm/s",
       ("bench.yaml:28: stage.speed", "above this stage's 30.48 mm/s")),
    _b("sim_stage_microstep", "a simulated bench's stage with another microstep",
       "  model: X-LSM500A", "  microstep: 0.1 um",
       ("bench.yaml:24: stage.microstep", "not the simulated stage's (0.047625 um")),
    _b("sim_stage_resolution", "a simulated bench's stage at another resolution",
       "  model: X-LSM500A", "  model: X-LSM500A\n  resolution: 128",
       ("stage.resolution", "the simulated X-LSM500A runs at 64")),
    _b("daq_channel_other_device", "the velocity channel on another device than daq.device",
       "velocity_channel: Dev1/ai0", "velocity_channel: Dev2/ai0",
       ("bench.yaml", "daq.velocity_channel: 'Dev2/ai0' is not on daq.device 'Dev1'")),
    _b("daq_channel_twice", "the reference channel the velocity channel too",
       "reference_channel: Dev1/ai1", "reference_channel: Dev1/ai0",
       ("daq.reference_channel: 'Dev1/ai0' is the velocity channel too",)),
    _b("bench_positions_twice", "two cylinders at one position in a list",
       "cylinder_positions: {first: 20 mm, pitch: 13.6 mm, count: 31}",
       "cylinder_positions: [20 mm, 30 mm, 30 mm]",
       ("cylinders 2 and 3 are both at 30 mm",)),
    _b("bench_chain_missing", "a simulated bench whose chain file does not exist",
       "chain: null", "chain: nochain.yaml",
       ("error: bench.yaml:5: chain:", "nochain.yaml: cannot read")),
    _b("bench_name_newline", "a line break in the bench's name", "name: simulated bench",
       'name: "sim\\nbench"', ("bench.yaml", "name")),
    _b("generator_nyquist", "a 8.92 kHz burst from a 10 kSa/s generator waveform",
       "sample_rate: 1 MSa/s", "sample_rate: 10 kSa/s", ("proto.yaml", "generator.sample_rate")),
    _b("piezo_limit", "3 um on a piezo limited to 50 V (gain 20, 0.05 um/V)",
       "piezo_max: 150 V", "piezo_max: 50 V",
       ("proto.yaml", "3 um", "2.487 um", "piezo_max",
        "peaks are unequal, so it may reach x1.005")),
    _b("generator_rate_200M", "generator sample_rate: 200 MSa/s (the driver's ceiling: 160)",
       "sample_rate: 1 MSa/s", "sample_rate: 200 MSa/s",
       ("bench.yaml", "generator.sample_rate", "160 MS/s")),
    _b("positions_beyond_travel", "cylinder positions past the stage's soft limits",
       "pitch: 13.6 mm", "pitch: 30 mm", ("bench.yaml", "cylinder_positions", "soft limits")),
    Case("burst_too_long", "a 1.8 s burst: 1.8 M waveform points (the generator holds 1 M)",
         RUN, ("proto.yaml", "burst.ltr", "1,000,000"),
         {"proto.yaml": _replace(proto("shape: narrowband", "width: 0.3 s"),
                                 "duration: 10 ms", "duration: 5 s")}),
    # -- amplitudes: peak or peak-to-peak, within the limits in the unit used ---------------
    _p("amplitude_bare_V", "amplitude '1 V' (neither Vpp nor Vpk)", "[0.5 um, 3 um]",
       "[1 V, 2 V]", ("proto.yaml", "amplitudes", "Vpp", "Vpk")),
    _p("amplitude_vpk_over", "6 Vpk on a 10 Vpp generator", "[0.5 um, 3 um]", "[6 Vpk]",
       ("proto.yaml", "6 Vpk", "5 Vpk", "generator.max_amplitude")),
    _p("amplitude_um_over", "30 um on a bench that reaches 5 um", "[0.5 um, 3 um]",
       "[0.5 um, 30 um]", ("proto.yaml", "30 um", "5 um")),
    _p("amplitude_below_minimum", "1 mVpp: below the generator's 2 mVpp at high impedance",
       "[0.5 um, 3 um]", "[1 mVpp, 1 Vpp]",
       ("proto.yaml", "amplitudes", "0.001 Vpp", "minimum 0.002 Vpp")),
    # -- counts, durations and the memory a protocol asks for -------------------------------
    _p("cylinders_bool", "cylinders: [true]", "cylinders: [1, 8, 16]", "cylinders: [true]",
       ("proto.yaml", "cylinders")),
    _p("settle_1h", "settle: 1 h", "settle: 10 ms", "settle: 1 h", ("proto.yaml", "settle")),
    _p("window_transit", "a 2.5 ms record of cylinder 16 (burst 2.35 ms + transit)",
       "duration: 10 ms", "duration: 2.5 ms", ("proto.yaml", "duration", "transit")),
    _p("record_too_long", "a record of 20 M samples (10 s at 2 MS/s)",
       "{rate: 200 kS/s, duration: 10 ms, pre_trigger: 0.5 ms}",
       "{rate: 2 MS/s, duration: 10 s, timeout: 1 min}", ("proto.yaml", "10,000,000")),
    Case("run_too_big", "100 amplitudes x 31 cylinders x 1 M samples (25 GiB)", RUN,
         ("proto.yaml", "GiB", "2 GiB"),
         {"proto.yaml": _replace(_replace(proto(
             "amplitudes: [0.5 um, 3 um]", "amplitudes: {start: 0.5 um, stop: 3 um, count: 100}"),
             "cylinders: [1, 8, 16]", "cylinders: all"), "duration: 10 ms", "duration: 5 s")}),
)  # fmt: skip
