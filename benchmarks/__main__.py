"""``python -m benchmarks NAME [NAME ...]``: run benchmarks, print their tables, save JSON.

Each benchmark is a module ``benchmarks/<name>.py`` with ``run() -> dict``. The dict holds the
benchmark's figures (flat keys such as ``wall_s``) and optionally ``table``: a list of row dicts
printed as a table. The whole dict is written to ``benchmarks/runs/<name>.json`` (untracked)
together with the machine it ran on, and each number is printed beside the recorded reference
in ``benchmarks/results/<name>.json`` (tracked; replace it by hand, with a commit, when a new
result is to become the reference). ``python -m benchmarks --list`` lists them.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import pkgutil
import platform
import sys
import time
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

#: where new results go (untracked, see .gitignore)
RESULTS = Path(__file__).resolve().parent / "runs"
#: the recorded results new ones are compared with (tracked)
REFERENCE = Path(__file__).resolve().parent / "results"


def compare_with_reference(result: dict[str, Any], reference: dict[str, Any]) -> list[str]:
    """Lines ``key: new (reference ref, new/ref x.xx)`` for the numbers both hold."""
    lines = []
    for key, value in result.items():
        ref = reference.get(key)
        numbers = (int, float)
        if key == "total_s" or isinstance(value, bool) or isinstance(ref, bool):
            continue
        if isinstance(value, numbers) and isinstance(ref, numbers) and ref != 0:
            lines.append(f"{key}: {value:.4g} (reference {ref:.4g}, new/ref {value / ref:.3g})")
    return lines


def available() -> list[str]:
    here = Path(__file__).resolve().parent
    return sorted(m.name for m in pkgutil.iter_modules([str(here)]) if not m.name.startswith("_"))


def format_table(rows: list[dict[str, Any]]) -> str:
    if not rows:
        return ""
    cols = list(dict.fromkeys(k for r in rows for k in r))

    def fmt(v: Any) -> str:
        if isinstance(v, float):
            return f"{v:.4g}"
        return str(v)

    cells = [[fmt(r.get(c, "")) for c in cols] for r in rows]
    widths = [max(len(c), *(len(row[i]) for row in cells)) for i, c in enumerate(cols)]
    lines = ["  ".join(c.ljust(w) for c, w in zip(cols, widths, strict=True))]
    lines.append("  ".join("-" * w for w in widths))
    lines += ["  ".join(v.ljust(w) for v, w in zip(row, widths, strict=True)) for row in cells]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks")
    parser.add_argument("names", nargs="*", help="benchmarks to run")
    parser.add_argument("--list", action="store_true", help="list the benchmarks")
    args = parser.parse_args(argv)
    names = available()
    if args.list or not args.names:
        print("benchmarks: " + ", ".join(names))
        return 0 if args.list else 2
    unknown = [n for n in args.names if n not in names]
    if unknown:
        print(f"unknown benchmark {unknown[0]!r}; choose from {', '.join(names)}", file=sys.stderr)
        return 2
    from daq.progress import ProgressDisplay

    with ProgressDisplay(len(args.names), unit="benchmark", stream=sys.stderr) as bar:
        for k, name in enumerate(args.names):
            if bar.live:
                bar.update(k, detail=f"{name} running")
            _run_one(name)
            bar.update(k + 1, detail=f"{name} done")
    return 0


def _run_one(name: str) -> None:
    """Run one benchmark, print its table and write its results."""
    RESULTS.mkdir(exist_ok=True)
    module = importlib.import_module(f"benchmarks.{name}")
    t0 = time.perf_counter()
    result: dict[str, Any] = module.run()
    result.setdefault("benchmark", name)
    result["total_s"] = time.perf_counter() - t0
    result["machine"] = {
        "python": platform.python_version(),
        "processor": platform.processor() or platform.machine(),
        "cpus": os.cpu_count(),
        "date": datetime.now(UTC).isoformat(timespec="seconds"),
    }
    print(f"== {name}")
    if result.get("table"):
        print(format_table(result["table"]))
    for key, value in result.items():
        if key not in ("table", "machine") and not isinstance(value, dict | list):
            print(f"{key}: {value:.4g}" if isinstance(value, float) else f"{key}: {value}")
    ref_path = REFERENCE / f"{name}.json"
    if ref_path.is_file():
        try:
            reference = json.loads(ref_path.read_text())
        except ValueError:
            reference = {}
        lines = compare_with_reference(result, reference)
        if lines:
            when = reference.get("machine", {}).get("date", "?")
            print(f"-- against the recorded reference ({when}):")
            print("\n".join(lines))
    out = RESULTS / f"{name}.json"
    out.write_text(json.dumps(result, indent=2, default=str) + "\n")
    print(f"written {out.relative_to(Path.cwd()) if out.is_relative_to(Path.cwd()) else out}")


if __name__ == "__main__":
    raise SystemExit(main())
