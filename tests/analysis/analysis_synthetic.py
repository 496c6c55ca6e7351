"""Synthetic run files with known answers, written through ``protocols.runfile``.

The chain: 31 cylinders, acoustic band [0, 3 kHz] and a first local-resonance band whose
onset falls linearly from 8.08 kHz (#1) to 5.4 kHz (#31) and whose cutoff falls from 10.0 kHz
to 8.01 kHz: the shape of the paper's graded chain. The velocities are Gaussian packets that
travel one cylinder per ``HOP_S``; at cylinder ``i`` the packet's frequency is ``freq(i)``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from instruments.burst import Burst, burst_waveform
from protocols.runfile import ChainInfo, RunFileWriter, ScanSpec

N = 31
RATE_HZ = 200_000.0
DURATION_S = 0.01
HOP_S = 0.1e-3
F_LTR_HZ = 8920.0
F_RTL_HZ = 6630.0


def chain() -> ChainInfo:
    x = np.linspace(0.0, 1.0, N)
    onset = 8080.0 + (5400.0 - 8080.0) * x
    cutoff = 10000.0 + (8010.0 - 10000.0) * x
    return ChainInfo(
        lengths_m=np.linspace(0.09, 0.11, N),
        diameter_m=0.0136,
        f0_N=5.0,
        beta_c=4.08e9,
        onset_Hz=np.stack([np.zeros(N), onset], axis=1),
        cutoff_Hz=np.stack([np.full(N, 3000.0), cutoff], axis=1),
    )


def time_s() -> NDArray[np.float64]:
    return np.arange(round(DURATION_S * RATE_HZ)) / RATE_HZ


def packet(
    t: NDArray[np.float64], f_Hz: float, delay_s: float, amp: float, sigma_s: float = 0.3e-3
) -> NDArray[np.float64]:
    t0 = 1.0e-3 + delay_s
    return amp * np.exp(-((t - t0) ** 2) / (2 * sigma_s**2)) * np.sin(2 * np.pi * f_Hz * (t - t0))


def scan_velocity(
    direction: str,
    freq: Callable[[int], float],
    gain: Callable[[int], float],
    amplitude: float = 1e-3,
) -> NDArray[np.float64]:
    """``[C, S]`` packets: cylinder ``i`` (0-based distance from the entry) at ``freq(i)``."""
    t = time_s()
    v = np.zeros((N, t.size))
    for c in range(N):
        i = c if direction == "ltr" else N - 1 - c
        v[c] = packet(t, freq(i), i * HOP_S, amplitude * gain(i))
    return v


def write_run(
    path: Path,
    directions: Sequence[str] = ("ltr", "rtl"),
    amplitudes: Sequence[float] = (0.5e-6, 1e-6, 2e-6, 4e-6),
    converting: Callable[[float], bool] = lambda a: a >= 2e-6,
    partial: Callable[[str, int, int], bool] | None = None,
    status: str = "complete",
) -> Path:
    """A run file. Above ``converting`` amplitude the packet reaches the far end and its
    frequency slides to the far cylinder's edge (down for LTR, up for RTL); below it, the
    packet dies out past the middle (transmission ~1e-8). ``partial(direction, a, c)`` True
    leaves a point unmeasured."""
    ch = chain()
    t = time_s()
    onset, cutoff = ch.onset_Hz[:, 1], ch.cutoff_Hz[:, 1]
    specs = []
    for d in directions:
        f_c = F_LTR_HZ if d == "ltr" else F_RTL_HZ
        specs.append(
            ScanSpec(
                d,
                np.asarray(amplitudes),
                "m",
                np.arange(1, N + 1, dtype=np.int32),
                t,
                f_c,
                cycles=5.0,
                drive_units="m",
            )
        )
    w = RunFileWriter.create(path, backend="dem", chain=ch, scans=specs)
    for d in directions:
        f_c = F_LTR_HZ if d == "ltr" else F_RTL_HZ
        target = cutoff[-1] if d == "ltr" else onset[0]
        burst = Burst(f_c, cycles=5.0)
        drive = burst_waveform(t, burst)
        for a, amp in enumerate(amplitudes):
            if converting(amp):

                def freq(i: int, f_c: float = f_c, target: float = target) -> float:
                    return f_c + (target - f_c) * i / (N - 1)

                def gain(i: int) -> float:
                    return 1.0 - 0.5 * i / (N - 1)
            else:

                def freq(i: int, f_c: float = f_c) -> float:
                    return f_c

                def gain(i: int) -> float:
                    return 1.0 if i < 12 else 10.0 ** (-(i - 11) * 0.2)

            v = scan_velocity(d, freq, gain, amplitude=amp * 1e3)
            for c in range(N):
                if partial is not None and partial(d, a, c):
                    continue
                w.write_point(d, a, c, v[c], amp * drive)
    w.close(status)  # type: ignore[arg-type]
    return path
