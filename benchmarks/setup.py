"""No hidden seconds (issue 18): what a command pays before its first result.

- ``build_chain``: the default chain built from scratch (memory caches cleared) in a fresh
  process, ``BUILDS`` times, with BLAS limited to one thread (``OPENBLAS_NUM_THREADS=1`` and
  friends) and with the default BLAS threads, while two CPU-bound processes (busy loops, started
  here) run beside it. Reported: the median and the largest build (s), and the time to import
  ``sim_backend.dem`` in that process (s). Target: < 0.1 s.
- the step-stability check of the simulated bench's DEM runs: the smoke protocol's two keys
  (LTR 0.5 um and 3 um at 200 kS/s, 30 ms, the default integrator with its step-doubling
  estimate, whose rerun at 2h is the checked step) and the regime's largest drive (4 delta0),
  in turn, each in a fresh process with no stability verdict in the user cache (the compiled
  kernel and step map on disk; the kernel loaded before timing): per key the check's time
  (``check_step`` called first, as ``simulate`` does), the run's time (``simulate`` with the
  estimate, the check then served from memory) and the check as a fraction of that run. For
  (a) the shipped default chain, whose verdict comes with the package
  (:mod:`sim_backend.dem.shipped_stability`); (b) a chain that does not ship (the default with
  ``preload=6 N``), computed: its first key, then its later keys (medians of ``CHECK_REPS``
  processes); (c) that chain in a new process,
  the verdict on disk; (d) its first key with no compiled step map on disk (the stability
  certificate, :mod:`sim_backend.dem.stability_certificate`, needs none: numba compiled the
  step map's grid scan here before the certificate). Target: < 5 % of the run.
- what the check adds to a fresh process's first run (both sides include the kernel's load from
  the cache folder): ``FIRST_RUN_REPS`` pairs of fresh processes, interleaved, each timing its
  first ``simulate`` (the chain that does not ship, LTR 0.5 um, 30 ms at 200 kS/s with the
  error estimate, whose rerun at 2h is checked) and then a second one (the run alone); one of
  each pair with no verdict in the user cache (the check is computed: one stability certificate,
  in turn, after the kernel's load), the other with the verdict on disk. Reported: the medians,
  their difference and that difference as a fraction of the first ``simulate`` and of the run.
- ``run_protocol smoke`` as a subprocess on the simulated bench, through the console script's
  entry point (``daq.cli.entry``, which also settles the interpreter's shutdown,
  :mod:`daq.cli.shutdown`): cold (an empty cache folder,
  ``$BIAFC_CACHE_DIR``: the kernel compiles) and warm (the same folder again), the time from the
  start of the process to its first measured point (the first ``point 1/`` line) and to its
  exit; the warm run ``WARM_REPS`` times, its median (and range) reported, since one run on a
  shared host varies by 30 %. Like the check's, these processes run with the bytecode cache on.
  Target: warm < 2 s.

Each figure is printed with the host's load average (``os.getloadavg``) at the time. The
check's subprocesses run with Python's bytecode cache on (``PYTHONDONTWRITEBYTECODE`` dropped),
as an installed package has it: otherwise every fresh process compiles the modules it imports
from source, a cost the check's first key would carry (it imports the step map) and a user's
process does not.
"""

from __future__ import annotations

import json
import multiprocessing
import os
import statistics
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path
from typing import Any

BUILDS = 7
BLAS_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS")
SMOKE_KEYS_M = (0.5e-6, 3.0e-6)  # smoke.yaml's amplitudes (displacement)
WARM_REPS = 5  # warm run_protocol smoke runs (the median is reported)
SMOKE_RATE_HZ = 200e3
DEM_DURATION_S = 30e-3  # the simulated bench's dem_duration_s
TARGETS = "build_chain < 0.1 s loaded; stability check < 5 % of the run; warm smoke < 2 s"

_BUILD_CODE = textwrap.dedent(
    """
    import json, time
    t0 = time.perf_counter()
    from sim_backend import dem
    from sim_backend.dem import chain as chain_mod
    from sim_backend.dem.threads import blas_threads
    t_import = time.perf_counter() - t0
    spec = dem.default_chain_spec()
    walls = []
    for _ in range({builds}):
        chain_mod._CACHE.clear()
        t0 = time.perf_counter()
        dem.build_chain(spec)
        walls.append(time.perf_counter() - t0)
    print(json.dumps({{"walls": walls, "import_s": t_import, "blas": blas_threads()}}))
    """
)


def _busy() -> None:  # pragma: no cover - runs in the child
    x = 0
    while True:
        x += 1


def _load() -> float:
    return round(os.getloadavg()[0], 2)


def _build_chain_rows() -> list[dict[str, Any]]:
    ctx = multiprocessing.get_context("spawn")
    busy = [ctx.Process(target=_busy, daemon=True) for _ in range(2)]
    for p in busy:
        p.start()
    rows = []
    try:
        time.sleep(1.0)  # let them take the cores
        for threads in ("1", "default"):
            env = dict(os.environ)
            for var in BLAS_VARS:
                env.pop(var, None)
                if threads == "1":
                    env[var] = "1"
            got = _json_from(_BUILD_CODE.format(builds=BUILDS), env)
            walls = sorted(got["walls"])
            rows.append(
                {
                    "what": f"build_chain, BLAS threads {threads}",
                    "blas_threads": ",".join(str(n) for n in got["blas"]),
                    "median_s": walls[len(walls) // 2],
                    "max_s": walls[-1],
                    "import_dem_s": got["import_s"],
                    "busy_processes": len(busy),
                    "load_1min": _load(),
                }
            )
    finally:
        for p in busy:
            p.terminate()
        for p in busy:
            p.join()
    return rows


_CHECK_CODE = textwrap.dedent(
    """
    import json, time
    from instruments.burst import Burst
    from sim_backend import dem
    from sim_backend.dem import step_limit
    from sim_backend.dem.shipped_stability import checked_step
    chain = dem.build_chain(dem.load_chain_with_settings(None, {settings!r}))
    rate = {rate!r}
    # the kernel loaded (not timed: it is no part of the check)
    dem.simulate(chain, [dem.Drive("ltr", "displacement", 1e-7, burst=Burst(8.92e3))],
                 duration_s=1e-4, sample_rate_Hz=rate)
    h = checked_step(chain, rate)
    out = []
    for a in [*{amplitudes!r}, 4.0 * chain.delta0_m]:
        d = dem.Drive("ltr", "displacement", a, burst=Burst(8.92e3))
        t0 = time.perf_counter()
        step_limit.check_step(chain, "blanes-moan4", h, [d])
        check_s = time.perf_counter() - t0
        run_s = float("nan")
        if {runs!r}:
            t0 = time.perf_counter()
            dem.simulate(chain, [d], duration_s={duration!r}, sample_rate_Hz=rate,
                         error_estimate=True)
            run_s = time.perf_counter() - t0
        out.append({{"amplitude_m": a, "check_s": check_s, "run_s": run_s}})
    print(json.dumps(out))
    """
)
NOT_SHIPPED = ["preload=6 N"]  # the default chain with one setting changed: not in the table


def _json_from(code: str, env: dict[str, str]) -> Any:
    """The JSON that a fresh ``python -c code`` process prints on its last line."""
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True,
        timeout=600,
    )  # fmt: skip
    return json.loads(out.stdout.strip().splitlines()[-1])


def _check_env(cache: Path) -> dict[str, str]:
    """A subprocess's environment: ``cache`` as the user cache folder, numba's own cache
    settings and ``PYTHONDONTWRITEBYTECODE`` dropped (module docstring)."""
    env = dict(os.environ, BIAFC_CACHE_DIR=str(cache))
    for var in ("NUMBA_CACHE_DIR", "NUMBA_CACHE_LOCATOR_CLASSES", "PYTHONDONTWRITEBYTECODE"):
        env.pop(var, None)
    return env


def _check_process(cache: Path, settings: list[str], runs: bool) -> list[dict[str, Any]]:
    """One fresh process checking the keys (and timing their runs) with ``cache`` as the user
    cache folder."""
    code = _CHECK_CODE.format(settings=settings, rate=SMOKE_RATE_HZ, amplitudes=list(SMOKE_KEYS_M),
                              runs=runs, duration=DEM_DURATION_S)  # fmt: skip
    rows: list[dict[str, Any]] = _json_from(code, _check_env(cache))
    return rows


def _forget_verdicts(cache: Path) -> None:
    (cache / "step-stability.json").unlink(missing_ok=True)


CHECK_REPS = 5


def _median_process(cache: Path, settings: list[str]) -> list[dict[str, Any]]:
    """:func:`_check_process` with no verdict on disk, ``CHECK_REPS`` times: per key the median
    check and run (one fresh process's first key varies by several ms on a loaded host)."""
    import statistics

    reps = []
    for _ in range(CHECK_REPS):
        _forget_verdicts(cache)
        reps.append(_check_process(cache, settings, runs=True))
    return [
        {
            "amplitude_m": keys[0]["amplitude_m"],
            "check_s": statistics.median(k["check_s"] for k in keys),
            "run_s": statistics.median(k["run_s"] for k in keys),
        }
        for keys in zip(*reps, strict=True)
    ]


def _stability_rows(cache: Path) -> list[dict[str, Any]]:
    # compile the kernel and the step map into the empty folder (not timed)
    _check_process(cache, NOT_SHIPPED, runs=False)
    rows = []

    def add(label: str, keys: list[dict[str, Any]], runs: list[dict[str, Any]]) -> None:
        for i, (key, run) in enumerate(zip(keys, runs, strict=True)):
            which = "first key" if i == 0 else "later key"
            rows.append(
                {
                    "what": f"stability check, {label}, {which} ltr "
                    f"{key['amplitude_m'] * 1e6:.3g} um",
                    "check_s": key["check_s"],
                    "run_s": run["run_s"],
                    "check_of_run": key["check_s"] / run["run_s"],
                    "load_1min": _load(),
                }
            )

    _forget_verdicts(cache)
    shipped = _check_process(cache, [], runs=True)
    add("shipped chain, no verdict in the user cache", shipped, shipped)
    computed = _median_process(cache, NOT_SHIPPED)
    add(f"chain not shipped, no verdict in the user cache, median of {CHECK_REPS} processes",
        computed, computed)  # fmt: skip
    on_disk = _check_process(cache, NOT_SHIPPED, runs=False)
    add("chain not shipped, new process, verdict on disk", on_disk, computed)
    _forget_verdicts(cache)
    for f in (cache / "numba").rglob("step_map.*"):
        f.unlink()
    cold = _check_process(cache, NOT_SHIPPED, runs=False)
    add("chain not shipped, no verdict, no compiled step map on disk", cold[:1], computed[:1])
    return rows


FIRST_RUN_REPS = 15
_FIRST_RUN_CODE = textwrap.dedent(
    """
    import json, time
    from instruments.burst import Burst
    from sim_backend import dem
    from sim_backend.dem.simulation import block_modes
    chain = dem.build_chain(dem.load_chain_with_settings(None, {settings!r}))
    block_modes(chain)
    d = dem.Drive("ltr", "displacement", {amplitude!r}, burst=Burst(8.92e3))
    walls = []
    for _ in range(2):
        t0 = time.perf_counter()
        dem.simulate(chain, [d], duration_s={duration!r}, sample_rate_Hz={rate!r},
                     error_estimate=True)
        walls.append(time.perf_counter() - t0)
    print(json.dumps({{"first_s": walls[0], "run_s": walls[1]}}))
    """
)


def _first_run_rows(cache: Path) -> list[dict[str, Any]]:
    """What the check adds to a fresh process's first ``simulate`` (module docstring); the kernel
    and the step map are compiled in ``cache`` already."""
    import statistics

    code = _FIRST_RUN_CODE.format(settings=NOT_SHIPPED, amplitude=SMOKE_KEYS_M[0],
                                  duration=DEM_DURATION_S, rate=SMOKE_RATE_HZ)  # fmt: skip
    got: dict[str, list[dict[str, float]]] = {
        "check computed": [],
        "verdict read from the cache": [],
    }
    load = _load()
    for _ in range(FIRST_RUN_REPS):
        for label in got:
            if label == "check computed":
                _forget_verdicts(cache)
            got[label].append(_json_from(code, _check_env(cache)))
    med = {
        label: {k: statistics.median(r[k] for r in rows) for k in ("first_s", "run_s")}
        for label, rows in got.items()
    }
    rows = [
        {
            "what": f"fresh process, first simulate (kernel load + check + run), {label}",
            "first_simulate_s": m["first_s"],
            "run_s": m["run_s"],
            "reps": FIRST_RUN_REPS,
            "load_1min": load,
        }
        for label, m in med.items()
    ]
    added = med["check computed"]["first_s"] - med["verdict read from the cache"]["first_s"]
    rows.append(
        {
            "what": "what the check adds to a fresh process's first simulate (difference of "
            "the medians, the kernel's load in both)",
            "check_s": added,
            "check_of_first_simulate": added / med["verdict read from the cache"]["first_s"],
            "check_of_run": added / med["verdict read from the cache"]["run_s"],
            "load_1min": _load(),
        }
    )
    return rows


def _smoke(cache: Path, out: Path, label: str) -> dict[str, Any]:
    env = _check_env(cache)  # with the bytecode cache, as an installed package has it
    load = _load()
    t0 = time.perf_counter()
    proc = subprocess.Popen(
        [sys.executable, "-m", "daq.cli.entry", "smoke", "--out", str(out)],  # the console script
        env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    )  # fmt: skip
    first = None
    lines = []
    assert proc.stdout is not None
    for line in proc.stdout:
        lines.append(line.rstrip())
        if first is None and line.lstrip().startswith("point 1/"):
            first = time.perf_counter() - t0
    rc = proc.wait()
    total = time.perf_counter() - t0
    if rc != 0:
        raise RuntimeError(f"run_protocol smoke ({label}) exited {rc}: " + " | ".join(lines[-5:]))
    return {
        "what": f"run_protocol smoke, {label}",
        "first_point_s": first if first is not None else float("nan"),
        "total_s": total,
        "load_1min": load,
    }


def run() -> dict[str, Any]:
    table: list[dict[str, Any]] = []
    table += _build_chain_rows()
    with tempfile.TemporaryDirectory(prefix="biafc-setup-") as tmp:
        table += _stability_rows(Path(tmp) / "cache")
        table += _first_run_rows(Path(tmp) / "cache")
        smoke_cache = Path(tmp) / "smoke-cache"
        cold = _smoke(smoke_cache, Path(tmp) / "cold.h5", "cold (empty cache folder)")
        warms = [
            _smoke(smoke_cache, Path(tmp) / f"warm{j}.h5", "warm (the same folder again)")
            for j in range(WARM_REPS)
        ]
        warm = {
            "what": f"run_protocol smoke, warm (the same folder again), median of {WARM_REPS}",
            "first_point_s": statistics.median(w["first_point_s"] for w in warms),
            "total_s": statistics.median(w["total_s"] for w in warms),
            "min_s": min(w["total_s"] for w in warms),
            "max_s": max(w["total_s"] for w in warms),
            "load_1min": max(w["load_1min"] for w in warms),
        }
        table += [cold, warm]
    builds = [r for r in table if r["what"].startswith("build_chain")]

    def rows(label: str, which: str = "") -> list[dict[str, Any]]:
        return [r for r in table if label in r["what"] and which in r["what"]]

    shipped = rows("shipped chain,", "first key")[0]
    computed = rows("not shipped, no verdict in", "first key")[0]
    later = rows("not shipped, no verdict in", "later key")
    on_disk = rows("verdict on disk")
    no_step_map = rows("no compiled step map")[0]
    out: dict[str, Any] = {
        "build_chain_1_thread_s": builds[0]["median_s"],
        "build_chain_default_threads_s": builds[1]["median_s"],
        "build_chain_max_s": max(r["max_s"] for r in builds),
        "import_dem_s": max(r["import_dem_s"] for r in builds),
        "stability_first_key_shipped_s": shipped["check_s"],
        "stability_first_key_shipped_of_run": shipped["check_of_run"],
        "stability_first_key_not_shipped_s": computed["check_s"],
        "stability_first_key_not_shipped_of_run": computed["check_of_run"],
        "stability_later_keys_max_of_run": max(r["check_of_run"] for r in later),
        "stability_on_disk_max_of_run": max(r["check_of_run"] for r in on_disk),
        "stability_first_key_no_step_map_s": no_step_map["check_s"],
        "first_simulate_check_computed_s": rows("first simulate (kernel", "check computed")[0][
            "first_simulate_s"
        ],
        "first_simulate_verdict_cached_s": rows("first simulate (kernel", "read from the cache")[0][
            "first_simulate_s"
        ],
        "check_added_to_first_simulate_s": rows("what the check adds")[0]["check_s"],
        "check_added_of_first_simulate": rows("what the check adds")[0]["check_of_first_simulate"],
        "check_added_of_run": rows("what the check adds")[0]["check_of_run"],
        "smoke_cold_first_point_s": cold["first_point_s"],
        "smoke_cold_s": cold["total_s"],
        "smoke_warm_first_point_s": warm["first_point_s"],
        "smoke_warm_s": warm["total_s"],
        "smoke_warm_min_s": warm["min_s"],
        "smoke_warm_max_s": warm["max_s"],
        "load_1min_end": _load(),
        "targets": TARGETS,
        "table": table,
    }
    return out
