"""``biafc check [BENCH.yaml] [--move]``: the preflight of a bench before a scan.

Connects every instrument of the bench file (default: the shipped simulated bench), prints what
each reports (identity, firmware, the settings that matter) beside what the bench file expects,
and flags every mismatch. ``--move`` also homes the stage and fires one low-amplitude burst at
one cylinder (signal level, velocity, carrier), then confirms the run's safe state (outputs read
back off, the stage at rest). Exit status: 0 all match; 1 a mismatch, or an instrument that did
not answer; 2 the request was refused (bad bench file, bad option); 3 after ``--move`` the safe
state not confirmed (what to switch off by hand is named).
"""

from __future__ import annotations

import argparse
import sys
from typing import Any, TextIO

from daq.cli.biafc import CliError
from protocols.one_line import first_line

__all__ = ["add_arguments", "print_findings", "run"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "bench",
        nargs="?",
        default=None,
        help="bench file (default: the shipped simulated bench, protocols/benches/sim_bench.yaml)",
    )
    p.add_argument(
        "--move",
        action="store_true",
        help="also home the stage and fire one low-amplitude burst at one cylinder",
    )
    p.add_argument("--cylinder", type=int, default=1, help="cylinder of the burst (default 1)")
    p.add_argument(
        "--direction",
        choices=("ltr", "rtl"),
        default="ltr",
        help="which end the burst enters (default ltr, at 8.92 kHz; rtl at 6.63 kHz)",
    )
    p.add_argument(
        "--amplitude",
        default="0.2 Vpp",
        help="generator amplitude of the burst, peak to peak (Vpp) or peak (Vpk) "
        "(default '0.2 Vpp')",
    )


def print_findings(findings: list[Any], out: TextIO) -> None:
    """A table: status, instrument, setting, the bench file's value, the instrument's."""
    rows = [("", "instrument", "setting", "bench file", "instrument says")]
    for f in findings:
        mark = {"ok": "ok", "MISMATCH": "MISMATCH", "info": "-"}[f.status]
        rows.append((mark, f.instrument, f.item, f.expected, f.found))
    widths = [max(len(r[i]) for r in rows) for i in range(4)]
    for r in rows:
        line = "  ".join(c.ljust(w) for c, w in zip(r[:4], widths, strict=True))
        print(f"{line}  {r[4]}".rstrip(), file=out)
    bad = [f for f in findings if f.status == "MISMATCH"]
    for f in bad:
        print(
            f"MISMATCH {f.instrument} {f.item}: {f.found} (bench file: {f.expected or '-'})"
            f"{': ' + f.hint if f.hint else ''}",
            file=out,
        )


def run(args: argparse.Namespace) -> int:
    from daq import preflight
    from daq.connect import BenchInUse, connect_bench
    from instruments.errors import DriverNotInstalledError, InstrumentError
    from instruments.units import UnitError
    from protocols.bench import default_bench_path, load_bench
    from protocols.schema import parse_amplitude
    from protocols.yamlfile import ConfigError

    try:
        bf = load_bench(args.bench)
    except (ConfigError, OSError) as exc:
        raise CliError(first_line(exc)) from None
    test = None
    if args.move:
        try:
            drive, vpp = parse_amplitude(args.amplitude)  # as a protocol's: Vpp or Vpk
        except UnitError as exc:
            raise CliError(f"--amplitude: {exc}") from None
        if drive != "generator_Vpp":
            raise CliError(
                f"--amplitude {args.amplitude!r}: give generator volts, e.g. '0.2 Vpp' or '0.1 Vpk'"
            )
        f_c = 8.92e3 if args.direction == "ltr" else 6.63e3
        test = preflight.BurstTest(args.direction, args.cylinder, f_c, amplitude_Vpp=vpp)
        why = bf.bench.amplitude_limit_error(vpp, preflight.burst_peak_factor(bf, test))
        if why is not None:
            raise CliError(f"--amplitude: {why}")
        if not 1 <= args.cylinder <= bf.bench.n_cylinders:
            raise CliError(f"--cylinder {args.cylinder}: choose 1..{bf.bench.n_cylinders}")
    name = args.bench or str(default_bench_path().relative_to(default_bench_path().parents[2]))
    kind = "simulated" if bf.bench.simulated else "lab"
    print(f"biafc check: {name} ({bf.bench.name!r}, {kind} bench)")
    try:
        inst = connect_bench(bf)
    except (BenchInUse, ConfigError, DriverNotInstalledError) as exc:  # refused, as run_protocol
        # refuses them (exit 2): another process drives the bench, the bench file, a driver not
        # installed (it was exit 1 here); nothing was opened
        print(f"biafc check: refused: {first_line(exc)}", file=sys.stderr)
        return 2
    except (InstrumentError, OSError) as exc:
        print(f"biafc check: cannot connect: {first_line(exc)}", file=sys.stderr)
        return 1
    unsafe = None
    try:
        findings = preflight.check_settings(bf, inst)
        movers = [
            f for f in findings if f.status == "MISMATCH" and f.instrument in ("generator", "stage")
        ]
        if test is not None and movers:  # nothing moves or fires on a bench that does not match
            # (an output already on, a generator that did not answer, limits beyond the travel)
            findings.append(
                preflight.Finding(
                    "burst",
                    "one burst",
                    "",
                    "not fired, the stage not homed",
                    "MISMATCH",
                    "--move needs the generator and stage to match first: "
                    + "; ".join(f"{f.instrument} {f.item}" for f in movers),
                )
            )
            test = None
        if test is not None:
            leaving = True  # on another error or a stop signal, until the burst test is done
            try:
                try:
                    findings += preflight.check_burst(bf, inst, test)
                except Exception as exc:  # as the settings' (preflight._attempt): one line
                    said = first_line(exc) if str(exc) else ""
                    if not isinstance(exc, InstrumentError | ValueError):  # not foreseen: name it
                        said = f"{type(exc).__name__}: {said}"
                    findings.append(
                        preflight.Finding(
                            "burst",
                            "one burst",
                            "",
                            said,
                            "MISMATCH",
                            "the burst test did not complete",
                        )
                    )
                leaving = False
            finally:  # the burst may have fired: its safe state is confirmed either way
                safe, is_unsafe = preflight.safe_state_finding(bf, inst)
                unsafe = safe if is_unsafe else None
                if is_unsafe and leaving:  # no table will follow: say it now
                    print(f"biafc check: UNSAFE: {safe.hint}", file=sys.stderr, flush=True)
            findings.append(safe)
    finally:
        inst.close()
    print_findings(findings, sys.stdout)
    if unsafe is not None:
        print(f"biafc check: UNSAFE: {unsafe.hint}", file=sys.stderr)
        return 3
    n_bad = sum(f.status == "MISMATCH" for f in findings)
    if n_bad:
        print(f"biafc check: {n_bad} mismatch(es): fix them before a scan", file=sys.stderr)
        return 1
    print(
        "biafc check: every instrument matches the bench file"
        + ("; the burst went through" if test is not None else "")
    )
    return 0
