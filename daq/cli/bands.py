"""``biafc bands [--chain CHAIN.yaml] [--set KEY=VALUE] [--csv FILE] [--bands B] [--check]``.

Quasi-band edges.

Prints, for every cylinder, the onset (q = 0) and cutoff (q = pi) edges of the first B bands in
kHz (band 0 is the acoustic band [0, c1]; band 1 the first local-resonance band). ``--check``
adds the continuum-beam edges and their relative difference.
"""

from __future__ import annotations

import argparse
import csv
import sys
from pathlib import Path

import numpy as np

from daq.cli.biafc import CliError
from daq.cli.out_check import can_write


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--chain", type=Path, help="chain file (YAML); default: the paper's chain")
    parser.add_argument(
        "--set",
        dest="settings",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="change a chain setting (diameter=12mm, preload=4N, n_modes=5; repeatable)",
    )
    parser.add_argument("--csv", type=Path, help="also write the table to this CSV file")
    parser.add_argument("--bands", type=int, default=3, help="number of bands B (default 3)")
    parser.add_argument(
        "--check", action="store_true", help="compare with the continuum beam edges"
    )


def run(args: argparse.Namespace) -> int:
    from sim_backend import dem

    if args.csv:
        can_write(args.csv, "--csv")  # before the table, not after it
    try:
        spec = dem.load_chain_with_settings(args.chain, args.settings)
    except dem.ChainFileError as exc:
        raise CliError(str(exc)) from None
    chain = dem.build_chain(spec)
    if not 1 <= args.bands <= chain.n_modes + 1:
        raise CliError(f"--bands: must be in 1..{chain.n_modes + 1} for {chain.n_modes} modes")
    bands = dem.quasi_bands(chain, args.bands)
    header = ["cylinder", "length_mm"]
    for b in range(args.bands):
        header += [f"band{b}_onset_kHz", f"band{b}_cutoff_kHz"]
    rows: list[list[str]] = []
    for i in range(chain.n):
        row = [str(i + 1), f"{chain.lengths_m[i] * 1e3:.3f}"]
        for b in range(args.bands):
            row += [f"{bands.onset_Hz[i, b] / 1e3:.4f}", f"{bands.cutoff_Hz[i, b] / 1e3:.4f}"]
        rows.append(row)
    print(
        f"# chain: {chain.n} cylinders, d = {chain.diameter_m * 1e3:g} mm, F0 = {chain.f0_N:g} N, "
        f"J = {chain.n_modes} ({spec.beam_theory}); beta_c = {chain.beta_c:.4g} N/m^1.5, "
        f"delta0 = {chain.delta0_m * 1e6:.4g} um, K = {chain.K_lin:.4g} N/m"
    )
    widths = [max(len(h), *(len(r[k]) for r in rows)) for k, h in enumerate(header)]
    print("  ".join(h.rjust(w) for h, w in zip(header, widths, strict=True)))
    for r in rows:
        print("  ".join(v.rjust(w) for v, w in zip(r, widths, strict=True)))
    if args.check:
        cont = dem.continuum_bands(chain, args.bands)
        with np.errstate(divide="ignore", invalid="ignore"):
            d_on = np.abs(bands.onset_Hz / cont.onset_Hz - 1.0)[:, 1:]
            d_cut = np.abs(bands.cutoff_Hz / cont.cutoff_Hz - 1.0)
        for b in range(args.bands):
            on = f"{np.nanmax(d_on[:, b - 1]) * 100:.3f} %" if b > 0 else "-"
            print(
                f"# band {b}: max |DEM/continuum - 1|: onset {on}, "
                f"cutoff {np.nanmax(d_cut[:, b]) * 100:.3f} %"
            )
    if args.csv:
        try:
            args.csv.parent.mkdir(parents=True, exist_ok=True)  # checked writable above
            with args.csv.open("w", newline="", encoding="utf-8") as fh:
                writer = csv.writer(fh)
                writer.writerow(header)
                writer.writerows(rows)
        except OSError as exc:
            raise CliError(f"--csv: cannot write {args.csv} ({exc.strerror})") from None
        print(f"# written {args.csv}", file=sys.stderr)
    return 0
