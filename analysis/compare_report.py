"""``biafc compare``'s work: predict a run, compare, write the figures and the table.

:func:`compare_run` runs the model on what the run did (:mod:`analysis.model_run`), compares
(:mod:`analysis.compare`) and writes into the output folder:

* ``compare_spatial_<dir>_<k>.png/pdf``: measured and model spatial-frequency maps side by side
  (one colour scale) at the smallest and the largest amplitude of each direction;
* ``compare_spectra_<dir>``: the far cylinder's spectrum at every amplitude, measured and model;
* ``compare_sweep``: transmission and far-end peak against amplitude, both directions;
* ``compare_residuals``: the per-cylinder residuals; ``residuals.csv`` the table;
* ``comparison.json``: figure of merit, counts, per-cylinder residuals and what was modelled.

The figures take most of the time (5.5 of 7.5 s on a ``biafc_sweep`` run): ``on_text`` gets the
table and the figure of merit before any is drawn, ``on_written`` each figure as it is saved.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from analysis.bands import band_edges
from analysis.compare import Comparison, compare_runs, format_table
from analysis.model_run import (
    RunSetup,
    chain_spec_of_run,
    predict,
    predicted_run,
    run_setup,
)
from analysis.spatial import spatial_frequency_map
from protocols.runfile import ChainInfo, RunData
from sim_backend.dem import ChainSpec, build_chain, quasi_bands

__all__ = ["CompareReport", "compare_run", "write_compare"]


@dataclass
class CompareReport:
    """What :func:`compare_run` did: the comparison, the setup, files written, model seconds."""

    comparison: Comparison
    setup: RunSetup
    chain_spec: ChainSpec
    predicted: RunData
    model_s: float
    files: dict[str, list[Path]] = field(default_factory=dict)
    #: figures not drawn, and why (name -> reason)
    not_drawn: dict[str, str] = field(default_factory=dict)
    json_path: Path | None = None
    csv_path: Path | None = None
    #: the run file's status (``complete``, ``aborted``, ...) and the model's solver
    run_status: str = "complete"
    solver: str = "dem"

    def text(self) -> str:
        s = self.setup
        lines = []
        if s.stroke_m_per_V is not None and s.amplifier_gain_V_per_V is not None:
            lines.append(
                f"drive: amplifier {s.amplifier_gain_V_per_V:g} V/V, piezo stroke "
                f"{s.stroke_m_per_V * 1e6:.4g} um/V (bench: {s.bench_stroke_m_per_V * 1e6:.4g})"
                if s.bench_stroke_m_per_V is not None
                else ""
            )
        clip = s.clip_m_per_s
        lines.append(
            "vibrometer clips at "
            + (f"{clip * 1e3:.4g} mm/s" if math.isfinite(clip) else "(unknown: not clipped)")
        )
        lines.append(
            f"model: diameter {self.chain_spec.diameter * 1e3:.4g} mm, preload "
            f"{self.chain_spec.preload:.4g} N, solver {self.solver}, {self.model_s:.1f} s"
        )
        if self.run_status != "complete":  # before, an aborted run was not said to be one
            lines.append(
                f"the run file is {self.run_status}: its points not measured are marked, not "
                "compared"
            )
        lines.append(format_table(self.comparison))
        return "\n".join(x for x in lines if x)


def compare_run(
    run: RunData,
    out_dir: str | Path | None,
    *,
    chain_spec: ChainSpec | None = None,
    piezo_stroke_m_per_V: float | None = None,
    solver: Literal["dem", "linear"] = "dem",
    on_text: Callable[[str], None] | None = None,
    on_written: Callable[[str, list[Path]], None] | None = None,
) -> CompareReport:
    """Predict ``run`` with ``chain_spec`` (default: the file's own chain, see
    :func:`analysis.model_run.chain_spec_of_run`), compare, and write the figures into
    ``out_dir`` (``None``: compute only).

    ``on_text(text)`` is called with :meth:`CompareReport.text` once the comparison is made,
    before any figure is drawn; ``on_written(name, paths)`` as each figure's files are saved."""
    spec = chain_spec if chain_spec is not None else chain_spec_of_run(run)
    setup = run_setup(run, piezo_stroke_m_per_V)
    n_run = len(run.chain.lengths_m)
    chain = build_chain(spec)
    if chain.n != n_run:
        raise ValueError(f"the chain has {chain.n} cylinders but the run file's chain has {n_run}")
    t0 = time.perf_counter()
    prediction = predict(setup, chain, solver=solver)
    model_s = time.perf_counter() - t0
    # the prediction carries the chain it was made with: its band edges, not the file's, are
    # what the figures draw (before, --chain drew the run file's chain's edges)
    pred = dataclasses.replace(predicted_run(run, prediction), chain=_chain_info(chain, run))
    cmp = compare_runs(run, pred, setup.clip_m_per_s)
    report = CompareReport(cmp, setup, spec, pred, model_s)
    report.run_status, report.solver = str(run.attrs.get("status", "unknown")), solver
    if on_text is not None:
        on_text(report.text())
    if out_dir is not None:
        write_compare(report, run, out_dir, on_written)
    return report


def _chain_info(chain: Any, run: RunData) -> ChainInfo:
    """The run file's ``/chain`` view of the built ``chain`` (as many bands as the file's)."""
    n_bands = np.atleast_2d(run.chain.onset_Hz).shape[1]
    return ChainInfo.of_model(chain, quasi_bands(chain, min(n_bands, chain.n_modes + 1)))


def write_compare(
    report: CompareReport,
    run: RunData,
    out_dir: str | Path,
    on_written: Callable[[str, list[Path]], None] | None = None,
) -> None:
    """Write the figures, ``residuals.csv`` and ``comparison.json`` of a :func:`compare_run`
    made with ``out_dir=None`` (``run``: the run it compared) into ``out_dir``;
    ``on_written(name, paths)`` as each figure's files are saved."""
    out = Path(out_dir)
    from analysis.plots.compare_plot import (
        plot_compare_residuals,
        plot_compare_spatial,
        plot_compare_spectra,
        plot_compare_sweep,
    )
    from analysis.plots.style import amplitude_label, save_figure
    from analysis.report import measured_amplitudes

    def save(fig: Any, name: str) -> None:
        report.files[name] = save_figure(fig, out, name)
        if on_written is not None:
            on_written(name, report.files[name])

    out.mkdir(parents=True, exist_ok=True)
    cmp, pred = report.comparison, report.predicted
    onset, cutoff = band_edges(pred.chain)  # the modelled chain's
    for d, dc in cmp.directions.items():
        scan, pscan = run.scans[d], pred.scans[d]
        f_range = dc.measured_sweep.f_range_Hz
        rate = scan.sample_rate_Hz
        # the lowest and highest amplitudes measured, as biafc figures picks them (the
        # protocol's largest, never measured in an aborted run, drew an all-hatched map)
        measured = measured_amplitudes(scan) or [0, len(scan.amplitudes) - 1]
        amps = list(dict.fromkeys([measured[0], measured[-1]]))
        for k, a in enumerate(amps):
            m = spatial_frequency_map(scan.velocity[a], scan.cylinders, rate, f_range)
            p = spatial_frequency_map(pscan.velocity[a], scan.cylinders, rate, f_range)
            label = amplitude_label(float(scan.amplitudes[a]), scan.amplitude_units)
            fig = plot_compare_spatial(
                m, p, dc.state[a], onset, cutoff, scan.f_center_Hz, f"{d.upper()} {label}"
            )
            name = f"compare_spatial_{d}_{'low' if k == 0 and len(amps) > 1 else 'high'}"
            save(fig, name)
        if dc.far_scanned():
            save(plot_compare_spectra(dc), f"compare_spectra_{d}")
        else:  # before: empty panels titled "(pending)" for a cylinder no point was planned on
            report.not_drawn[f"compare_spectra_{d}"] = (
                f"the far cylinder #{dc.measured_sweep.far} is not in the run's protocol"
            )
    if any(dc.sweep_scanned() for dc in cmp.directions.values()):
        save(plot_compare_sweep(cmp), "compare_sweep")
    else:
        report.not_drawn["compare_sweep"] = (
            "no direction has its entry and far cylinders in the run's protocol"
        )
    save(plot_compare_residuals(cmp), "compare_residuals")
    report.csv_path = out / "residuals.csv"
    with report.csv_path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(
            [
                "cylinder",
                "points",
                "spectral_residual",
                "time_residual",
                "noise_floor",
                "spectral_noise_floor",
            ]
        )
        for c, n, s, t, f, sn in zip(
            cmp.cylinders,
            cmp.n_points,
            cmp.spectral_residual,
            cmp.time_residual,
            cmp.noise_residual,
            cmp.spectral_noise_per_cylinder(),
            strict=True,
        ):
            w.writerow([int(c), int(n), _fmt(s), _fmt(t), _fmt(f), _fmt(sn)])
    summary: dict[str, Any] = cmp.as_dict()
    s = report.setup
    summary["run_file"] = run.path.name
    summary["run_status"] = report.run_status
    summary["model"] = {
        "chain": report.chain_spec.model_dump(mode="json"),
        "amplifier_gain_V_per_V": s.amplifier_gain_V_per_V,
        "piezo_stroke_m_per_V": s.stroke_m_per_V,
        "bench_piezo_stroke_m_per_V": s.bench_stroke_m_per_V,
        "vibrometer_clip_m_per_s": s.clip_m_per_s if math.isfinite(s.clip_m_per_s) else None,
        "model_s": report.model_s,
        "solver": report.solver,
    }
    summary["points_per_direction"] = {
        d: {
            st: int(np.count_nonzero(dc.state == st))
            for st in ("ok", "clipped", "failed", "pending")
        }
        | {"far_at_noise_floor": int(np.count_nonzero(dc.at_noise_floor))}
        for d, dc in cmp.directions.items()
    }
    report.json_path = out / "comparison.json"
    report.json_path.write_text(json.dumps(summary, indent=2))


def _fmt(x: float) -> str:
    return f"{x:.6g}" if math.isfinite(x) else ""
