"""``biafc warmup``: compile (or load) the DEM kernel ahead of time, and check the default chain's
step stability at the shipped protocols' sample rates, so that the first run starts at once (the
stability check compiles nothing: :mod:`sim_backend.dem.stability_certificate`). Prints what it
did and where the cache is (the user's cache folder)."""

from __future__ import annotations

import argparse
import time
from typing import Any

__all__ = ["add_arguments", "compile_kernel", "run"]

#: sample rates of the shipped protocols (Hz): the simulated bench runs the DEM at these
RATES_HZ = (200e3, 500e3)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--quiet", action="store_true", help="print only the summary line")


def compile_kernel(chain: Any = None) -> float:
    """Compile (or load) the DEM kernel in this process, as a first run would, with one short
    run of ``chain`` (default: the default chain); returns the seconds it took. A study calls
    it before its workers start, so that they load the kernel from the cache folder instead
    of each compiling it while the progress display counts the time as cells'."""
    from instruments.burst import Burst
    from sim_backend import dem

    built = chain if chain is not None else dem.build_chain(dem.default_chain_spec())
    t1 = time.perf_counter()
    weak = dem.Drive("ltr", "displacement", 0.1 * built.delta0_m, burst=Burst(8.92e3, 5.0))
    dem.simulate(built, [weak], duration_s=2e-4, sample_rate_Hz=RATES_HZ[0])
    return time.perf_counter() - t1


def run(args: argparse.Namespace) -> int:
    from daq.cli import compile_notice

    if not args.quiet:
        compile_notice.install()
    t0 = time.perf_counter()
    import numpy as np

    from sim_backend import dem
    from sim_backend.dem.kernel_cache import cache_note

    t_import = time.perf_counter() - t0
    t1 = time.perf_counter()
    chain = dem.build_chain(dem.default_chain_spec())
    t_chain = time.perf_counter() - t1
    t_kernel = compile_kernel(chain)
    t1 = time.perf_counter()
    # as the simulated bench runs it: a generator waveform, with the step-doubling estimate
    # (whose step 2h is checked for stability up to the drive's overlap)
    t = np.arange(400) / 1e6
    wave = np.sin(2 * np.pi * 8.92e3 * t) * np.exp(-(((t - 2e-4) / 1.2e-4) ** 2))
    for rate in RATES_HZ:
        strong = dem.Drive("ltr", "displacement", 4.0 * chain.delta0_m, waveform=(wave, 1e6))
        dem.simulate(chain, [strong], duration_s=1e-4, sample_rate_Hz=rate, error_estimate=True)
    t_stab = time.perf_counter() - t1
    print(
        f"warm: DEM kernel ready in {t_kernel:.1f} s (imports {t_import:.1f} s, default chain "
        f"{t_chain * 1e3:.0f} ms, stability verdicts {t_stab:.1f} s); {cache_note()}"
    )
    return 0
