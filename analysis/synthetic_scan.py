"""Synthetic measurements for proving :mod:`analysis.calibrate`: a scan of a chain the fit is
not told about, written as a run file that looks like one from the simulated bench.

The "true" chain (``true_spec``) and the true piezo stroke (``stroke_factor`` times the
bench's) drive one batched DEM run (every direction and amplitude, every cylinder); each
point then gets its own trigger jitter (a random time shift, normal with ``jitter_s`` RMS,
applied exactly as a phase ramp), white vibrometer noise (``noise_m_per_s`` RMS) and the
vibrometer's clipping. The file records what the lab believes: the shipped simulated bench
(its amplifier gain and stroke), the default chain in ``/chain`` and the vibrometer range
read back, so a fit that reads the file starts from the defaults.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from analysis.model_run import _on_time_axis, with_resonator_damping
from instruments.burst import Burst
from protocols.bench import default_bench_path, parse_bench
from protocols.runfile import ChainInfo, RunFileWriter, ScanSpec
from sim_backend.dem import ChainSpec, Drive, build_chain, default_chain_spec, quasi_bands, simulate

__all__ = ["INPUTS_HZ", "write_synthetic_scan"]

#: the paper's input frequencies (Hz)
INPUTS_HZ: Mapping[str, float] = {"ltr": 8.92e3, "rtl": 6.63e3}


def write_synthetic_scan(
    path: str | Path,
    *,
    true_spec: ChainSpec,
    stroke_factor: float = 1.0,
    amplitudes_m: Sequence[float] = (20e-9, 2e-6),
    directions: Sequence[str] = ("ltr", "rtl"),
    cylinders: Sequence[int] | None = None,
    cycles: float = 5.0,
    duration_s: float = 12e-3,
    pre_trigger_s: float = 0.5e-3,
    sample_rate_Hz: float = 200e3,
    noise_m_per_s: float = 2e-6,
    jitter_s: float = 1e-6,
    seed: int = 0,
    failed: Sequence[tuple[str, int, int]] = (),
    sensitivity_m_per_s_per_V: float = 0.05,
) -> Path:
    """Write the synthetic scan to ``path`` (see the module docstring) and return it.

    ``amplitudes_m``: the protocol's amplitudes (actuator displacement the bench believes it
    sends, m); ``failed``: (direction, amplitude index, cylinder index) points marked failed;
    ``sensitivity_m_per_s_per_V``: the vibrometer range read back (it clips at 10 V).
    """
    rng = np.random.default_rng(seed)
    bench_text = default_bench_path().read_text(encoding="utf-8")
    bench = parse_bench(bench_text).bench
    sens = float(sensitivity_m_per_s_per_V)
    clip = sens * min(10.0, float(bench.daq.velocity_range))
    chain = build_chain(true_spec)
    cyl = np.arange(1, chain.n + 1) if cylinders is None else np.asarray(cylinders)
    drives = [
        Drive(d, "displacement", float(a) * stroke_factor, Burst(INPUTS_HZ[d], cycles=cycles))  # type: ignore[arg-type]
        for d in directions
        for a in amplitudes_m
    ]
    res = simulate(
        chain,
        drives,
        duration_s=duration_s,
        sample_rate_Hz=sample_rate_Hz,
        cylinders=[int(c) for c in cyl],
        record=("velocity", "drive"),
    )
    n_pre = round(pre_trigger_s * sample_rate_Hz)
    n_s = round(duration_s * sample_rate_Hz)
    t = (np.arange(n_s + n_pre) - n_pre) / sample_rate_Hz
    nominal = build_chain(default_chain_spec())
    bands = quasi_bands(nominal, 3)
    info = ChainInfo(
        lengths_m=np.asarray(nominal.lengths_m),
        diameter_m=float(nominal.diameter_m),
        f0_N=float(nominal.f0_N),
        beta_c=float(nominal.beta_c),
        onset_Hz=np.asarray(bands.onset_Hz),
        cutoff_Hz=np.asarray(bands.cutoff_Hz),
    )
    amps = np.asarray(amplitudes_m, dtype=np.float64)
    specs = [
        ScanSpec(d, amps, "m", cyl.astype(np.int32), t, INPUTS_HZ[d], cycles=cycles)
        for d in directions
    ]
    snapshot = {"read_back": {"vibrometer": {"range": f"VD-09 {sens * 1e3:g}mm/s/V",
                                             "sensitivity_m_per_s_per_V": sens}},
                "synthetic": "analysis.synthetic_scan (truth withheld)"}  # fmt: skip
    w = RunFileWriter.create(
        path,
        backend="sim",
        chain=info,
        scans=specs,
        bench_yaml=bench_text,
        snapshot=snapshot,
        swmr=False,
    )
    bad = set(failed)
    rate = float(sample_rate_Hz)
    r = 0
    gain_V = 1.0 / (bench.amplifier.gain * bench.amplifier.piezo_stroke)
    for d in directions:
        for a in range(len(amps)):
            for c in range(len(cyl)):
                if (d, a, c) in bad:
                    w.mark_failed(d, a, c)
                    continue
                v = _on_time_axis(
                    res.time_s, _delayed(res.velocity[r, c], rng.normal(0.0, jitter_s), rate), t
                )
                v = v + rng.normal(0.0, noise_m_per_s, size=v.shape)
                v = np.clip(v, -clip, clip)
                drive_V = _on_time_axis(res.time_s, res.drive[r], t) * gain_V / stroke_factor
                w.write_point(d, a, c, v, drive_V)
            r += 1
    w.close("complete")
    return Path(path)


def _delayed(v: np.ndarray, delay_s: float, rate_Hz: float) -> np.ndarray:
    """``v`` delayed by ``delay_s`` exactly (band-limited: a phase ramp on the zero-padded
    spectrum; a linear interpolation would also low-pass the record by a fraction of a per
    cent at 9 kHz, which a calibration of the stroke would notice)."""
    n = v.size
    spec = np.fft.rfft(v, 2 * n)
    f = np.fft.rfftfreq(2 * n, 1.0 / rate_Hz)
    return np.fft.irfft(spec * np.exp(-2j * np.pi * f * delay_s), 2 * n)[:n]


def withheld_chain() -> tuple[ChainSpec, float]:
    """The chain and stroke factor of the calibration proof: F0 = 4.3 N (default 5 N),
    diameter 13.9 mm (13.6 mm), resonator damping ratio 0.005 (Q = 100; default 0.002), the
    piezo's stroke x0.8 (what the bench file says is 0.05 um/V, the truth 0.04 um/V)."""
    base = default_chain_spec()
    spec = with_resonator_damping(
        base.model_copy(update={"preload": 4.3, "diameter": 13.9e-3}), 0.005
    )
    return spec, 0.8


#: the scan of the calibration proof (benchmarks/calibrate.py, docs/calibration.md)
PROOF_SCAN: Mapping[str, object] = {
    "amplitudes_m": (20e-9, 50e-9, 0.5e-6, 2e-6, 4e-6),
    "duration_s": 12e-3,
    "noise_m_per_s": 2e-6,
    "jitter_s": 2e-6,
    "seed": 7,
}


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m analysis.synthetic_scan OUT.h5``: write the calibration proof's scan."""
    import argparse

    parser = argparse.ArgumentParser(
        prog="python -m analysis.synthetic_scan",
        description="write the synthetic scan of the calibration proof (truth withheld)",
    )
    parser.add_argument("out", type=Path, help="run file to create (.h5)")
    args = parser.parse_args(argv)
    spec, factor = withheld_chain()
    write_synthetic_scan(args.out, true_spec=spec, stroke_factor=factor, **PROOF_SCAN)  # type: ignore[arg-type]
    print(f"written {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
