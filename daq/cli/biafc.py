"""``biafc``: the command-line entry point; each subcommand lives in its own module.

A subcommand module ``daq/cli/<name>.py`` defines ``add_arguments(parser)`` and
``run(args) -> int``. Modules are imported only when their subcommand runs, so ``biafc bands``
does not pay for Qt or matplotlib.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from daq.cli.stop_signals import StopSignal, stop_signals_interrupt

#: subcommand -> (module under daq.cli, one-line help)
SUBCOMMANDS: dict[str, tuple[str, str]] = {
    "bands": ("bands", "per-cylinder quasi-band edges of a chain"),
    "simulate": ("simulate", "one DEM run written as a run file"),
    "accuracy": ("accuracy", "error against run time of the integrators"),
    "stability": ("stability", "stiff and extreme cases, each with a verdict"),
    "figures": ("figures", "the paper's figures from a run file"),
    "regime": ("regime", "transmission and output peak against amplitude, from the model"),
    "compare": ("compare", "the model on what a run did, beside the measurement"),
    "calibrate": ("calibrate", "fit the chain model to a scan's linear points"),
    "repair": ("repair", "make a run file or study output left by a killed writer readable"),
    "check": ("check", "preflight: every instrument against the bench file"),
    "study": ("study", "a design study on the model, on Dask (serial, local or a cluster)"),
    "gui": ("gui", "the bench window"),
    "warmup": ("warmup", "compile the DEM kernel ahead of time (it happens once)"),
}


class CliError(Exception):
    """A user error reported as one line (exit status 2)."""


def _load(name: str):  # type: ignore[no-untyped-def]
    module_name, _ = SUBCOMMANDS[name]
    return importlib.import_module(f"daq.cli.{module_name}")


#: the commands that may run the DEM, so compile its kernel on first use (before, regime, compare,
#: calibrate and figures --alpha-sweep sat 11-13 s silent on an empty cache; a second reader)
COMPILING = (
    "simulate", "accuracy", "stability", "regime", "compare", "calibrate", "figures", "check",
)  # fmt: skip


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = argparse.ArgumentParser(
        prog="biafc", description="biafc-lab: bench software for BiAFC experiments"
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, (_, help_text) in SUBCOMMANDS.items():
        sub.add_parser(name, help=help_text, add_help=False)
    if not argv or argv[0] in ("-h", "--help"):
        parser.print_help()
        return 0 if argv else 2
    name = argv[0]
    if name in COMPILING:  # may compile the DEM kernel: said once, with the time it takes
        from daq.cli import compile_notice

        compile_notice.install()
    if name not in SUBCOMMANDS:
        parser.error(f"unknown command {name!r} (choose from {', '.join(SUBCOMMANDS)})")
    try:
        module = _load(name)
    except ModuleNotFoundError as exc:
        print(f"biafc {name}: not available in this installation ({exc})", file=sys.stderr)
        return 2
    sub_parser = argparse.ArgumentParser(prog=f"biafc {name}", description=SUBCOMMANDS[name][1])
    module.add_arguments(sub_parser)
    args = sub_parser.parse_args(_negative_values_joined(argv[1:]))
    try:
        if name == "gui":  # the window closes on them itself (daq.gui.stop_signals)
            return int(module.run(args) or 0)
        with stop_signals_interrupt():
            return int(module.run(args) or 0)
    except CliError as exc:
        print(f"biafc {name}: error: {exc}", file=sys.stderr)
        return 2
    except StopSignal as exc:  # SIGTERM, SIGHUP: through the Ctrl-C path, files closed
        _say(f"biafc {name}: interrupted by {exc}")
        return 128 + exc.signum
    except KeyboardInterrupt:
        print(f"biafc {name}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # the reader stopped early (biafc bands | head): not a failure
        _quiet_stdout()
        return 0


def _negative_values_joined(argv: list[str]) -> list[str]:
    """``--amplitude -2um`` as ``--amplitude=-2um``: argparse takes a value that starts with a
    minus sign and is not a bare number for an option, and said "expected one argument"; the
    option's own check then says what is wrong with the value."""
    out: list[str] = []
    i = 0
    while i < len(argv):
        tok = argv[i]
        nxt = argv[i + 1] if i + 1 < len(argv) else ""
        if (
            tok.startswith("--")
            and "=" not in tok
            and len(nxt) > 1
            and nxt[0] == "-"
            and (nxt[1].isdigit() or nxt[1] == ".")
        ):
            out.append(f"{tok}={nxt}")
            i += 2
            continue
        out.append(tok)
        i += 1
    return out


def _say(line: str) -> None:
    """One line to stderr, and nothing when it is gone (SIGHUP: the terminal closed)."""
    try:
        print(line, file=sys.stderr, flush=True)
    except (OSError, ValueError):
        pass


def _quiet_stdout() -> None:
    """Point stdout at the null device, so that the interpreter's last flush of a closed pipe
    raises nothing (Python's own advice for SIGPIPE)."""
    import os

    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):
        pass
    finally:
        os.close(devnull)


if __name__ == "__main__":  # python -m daq.cli.biafc: the console script's own path, so that
    # the commands' CliError is this module's as imported (run as __main__, it is a second copy
    # of the module whose class the commands' refusals are not: they escaped as tracebacks)
    from daq.cli.shutdown import biafc

    raise SystemExit(biafc())
