"""The analog path from the chain to the digitiser's numbers: pure functions, no state.

velocity (m/s) -> vibrometer decoder (range scaling, decoder noise, clipping at its full scale)
-> digitiser (input noise, clipping at the input range, quantisation). Plus the small helpers that
put a DEM record on the digitiser's time grid and coerce rates and ranges like an NI device.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from instruments.errors import LimitError

__all__ = [
    "INPUT_RANGES_V",
    "coerce_input_range",
    "coerce_sample_rate",
    "decoder_output",
    "digitise",
    "on_grid",
]

#: bipolar input ranges (+/- V) of a typical NI multifunction device
INPUT_RANGES_V: tuple[float, ...] = (0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0)


def coerce_input_range(requested_V: float, what: str = "input range") -> float:
    """Smallest supported range >= the requested +/- volts (as NI-DAQmx does)."""
    for r in INPUT_RANGES_V:
        if requested_V <= r * (1.0 + 1e-12):
            return r
    raise LimitError(
        f"digitiser {what} +/-{requested_V:g} V exceeds the device's largest range "
        f"+/-{INPUT_RANGES_V[-1]:g} V"
    )


def coerce_sample_rate(requested_Hz: float, max_rate_Hz: float, timebase_Hz: float) -> float:
    """The rate the device really uses: ``timebase / k`` for an integer divisor ``k`` closest to
    the request; refuses rates above ``max_rate_Hz``."""
    if requested_Hz > max_rate_Hz * (1.0 + 1e-9):
        raise LimitError(
            f"digitiser sample rate {requested_Hz:g} S/s exceeds the device maximum "
            f"{max_rate_Hz:g} S/s"
        )
    k_min = math.ceil(timebase_Hz / max_rate_Hz - 1e-9)
    k = max(k_min, round(timebase_Hz / requested_Hz))
    return timebase_Hz / k


def on_grid(
    src_time_s: NDArray[np.float64], values: NDArray[np.float64], dst_time_s: NDArray[np.float64]
) -> NDArray[np.float64]:
    """``values [S_src]`` (or ``[R, S_src]``) on a uniform ``src_time_s [S_src]`` taken onto
    ``dst_time_s [S]``; zero outside the source window (the chain is at rest before the
    trigger). Exact copy when the grids coincide; otherwise four-point (cubic) Lagrange
    interpolation, linear in the first and last interval. Linear interpolation throughout
    low-passed the record: the decoder's 7.3 us delay, a fraction of a sample, took 1.0 % off an
    8.92 kHz burst at 200 kS/s and 0.14 % at 500 kS/s (0.014 % and 0.0003 % now), about half
    of the 0.24 % by which ``biafc calibrate`` read the stroke low on the simulated bench. A
    source grid that is not uniform is interpolated linearly."""
    src = np.asarray(src_time_s, dtype=np.float64)
    dst = np.asarray(dst_time_s, dtype=np.float64)
    vals = np.asarray(values, dtype=np.float64)
    if src.shape[0] >= 2:
        dt = (src[-1] - src[0]) / (src.shape[0] - 1)
        offset = (dst[0] - src[0]) / dt
        same_step = dst.shape[0] < 2 or abs((dst[1] - dst[0]) - dt) <= 1e-9 * dt
        k0 = round(offset)
        if same_step and abs(offset - k0) < 1e-6:
            out = np.zeros(vals.shape[:-1] + dst.shape, dtype=np.float64)
            lo = max(0, -k0)
            hi = min(dst.shape[0], src.shape[0] - k0)
            if hi > lo:
                out[..., lo:hi] = vals[..., lo + k0 : hi + k0]
            return out
        uniform = src.shape[0] >= 4 and bool(np.all(np.abs(np.diff(src) - dt) <= 1e-9 * abs(dt)))
        if uniform:
            return _lagrange4(vals, (dst - src[0]) / dt)
    if vals.ndim == 1:
        return np.interp(dst, src, vals, left=0.0, right=0.0)
    return np.stack([np.interp(dst, src, row, left=0.0, right=0.0) for row in vals])


def _lagrange4(vals: NDArray[np.float64], x: NDArray[np.float64]) -> NDArray[np.float64]:
    """``vals [..., S_src]`` at fractional sample positions ``x [S]``: cubic Lagrange on the four
    samples around each point, linear in the first and last interval, zero outside
    ``[0, S_src - 1]``."""
    n = vals.shape[-1]
    out = np.zeros(vals.shape[:-1] + x.shape, dtype=np.float64)
    inside = (x >= 0.0) & (x <= n - 1)
    xi = np.where(inside, x, 0.0)
    k = np.minimum(np.floor(xi).astype(np.int64), n - 2)
    tau = xi - k
    cubic = inside & (k >= 1) & (k <= n - 3)
    linear = inside & ~cubic
    if np.any(linear):
        kl, tl = k[linear], tau[linear]
        out[..., linear] = (1.0 - tl) * vals[..., kl] + tl * vals[..., kl + 1]
    if np.any(cubic):
        kc, t = k[cubic], tau[cubic]
        w = (
            -t * (t - 1.0) * (t - 2.0) / 6.0,
            (t + 1.0) * (t - 1.0) * (t - 2.0) / 2.0,
            -(t + 1.0) * t * (t - 2.0) / 2.0,
            (t + 1.0) * t * (t - 1.0) / 6.0,
        )
        out[..., cubic] = sum(wj * vals[..., kc + j - 1] for j, wj in enumerate(w))
    return out


def decoder_output(
    velocity_m_per_s: NDArray[np.float64],
    sensitivity_m_per_s_per_V: float,
    full_scale_V: float,
    noise_m_per_s_rms: float,
    rng: np.random.Generator,
) -> NDArray[np.float64]:
    """The vibrometer decoder's analog output (V), shape of the input: velocity plus decoder
    noise, divided by the range's sensitivity, clipped at +/- ``full_scale_V``."""
    v = np.asarray(velocity_m_per_s, dtype=np.float64)
    if noise_m_per_s_rms > 0:
        v = v + rng.normal(0.0, noise_m_per_s_rms, size=v.shape)
    return np.clip(v / sensitivity_m_per_s_per_V, -full_scale_V, full_scale_V)


def digitise(
    volts: NDArray[np.float64],
    range_V: float,
    bits: int,
    noise_V_rms: float,
    rng: np.random.Generator,
) -> NDArray[np.float64]:
    """What the ADC returns (V): input plus noise, clipped to the range and quantised to
    ``bits`` over +/- ``range_V`` (codes ``-2**(bits-1) .. 2**(bits-1) - 1``)."""
    x = np.asarray(volts, dtype=np.float64)
    if noise_V_rms > 0:
        x = x + rng.normal(0.0, noise_V_rms, size=x.shape)
    lsb = 2.0 * range_V / 2**bits
    half = 2 ** (bits - 1)
    codes = np.clip(np.round(x / lsb), -half, half - 1)
    return codes * lsb
