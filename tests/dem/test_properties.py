"""Property-based tests (hypothesis) over random small chains and drives: energy never grows
without input, momentum balance with both ends free, results independent of batch composition."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from instruments.burst import Burst
from sim_backend import dem
from sim_backend.dem.spec import ChainSpec

RATE = 250e3
# a few lengths only, so that the cylinders' beam modes come from the cache
LENGTHS_MM = (90.0, 95.0, 100.0, 105.0, 110.0)
FAST = settings(max_examples=6, deadline=None, derandomize=True)


@st.composite
def chains(draw: st.DrawFn, far_end: str | None = None, damped: bool | None = None) -> dem.Chain:
    n = draw(st.integers(1, 5))
    lengths = [f"{draw(st.sampled_from(LENGTHS_MM)):g} mm" for _ in range(n)]
    damp = draw(st.booleans()) if damped is None else damped
    spec = ChainSpec.model_validate(
        {
            "lengths": lengths,
            "n_modes": draw(st.integers(1, 3)),
            "far_end": far_end or draw(st.sampled_from(["wall", "free"])),
            "preload": f"{draw(st.sampled_from([1.0, 5.0, 20.0])):g} N",
            "damping": {
                "bending_mode_ratio": 0.01 if damp else 0.0,
                "contact_dashpot_ratio": 0.01 if damp else 0.0,
            },
        }
    )
    return dem.build_chain(spec)


@st.composite
def drives(draw: st.DrawFn, chain: dem.Chain, kind: str | None = None) -> dem.Drive:
    k = kind or draw(st.sampled_from(["displacement", "force"]))
    level = draw(st.floats(0.01, 3.0))
    amp = level * (chain.delta0_m if k == "displacement" else chain.f0_N)
    burst = Burst(draw(st.floats(3e3, 12e3)), draw(st.floats(2.0, 6.0)))
    direction = draw(st.sampled_from(["ltr", "rtl"]))
    return dem.Drive(direction, k, amp, burst=burst)  # type: ignore[arg-type]


@FAST
@given(data=st.data())
def test_energy_never_grows_without_input(data: st.DataObject) -> None:
    """H_end - H_0 <= W: equal (to the integrator's error) undamped, below it damped."""
    chain = data.draw(chains())
    ds = [data.draw(drives(chain)) for _ in range(2)]
    res = dem.simulate(chain, ds, duration_s=2e-3, sample_rate_Hz=RATE, dt_s=0.5e-6)
    assert res.meta["finite"]
    work, gain = res.meta["input_work_J"], res.meta["energy_gain_J"]
    if res.meta["damped"]:
        assert np.all(gain <= work + 1e-6 * np.abs(work)), (gain, work)
    else:
        # equal to the integrator's error; short bursts (2 cycles) on tiny chains reach 1e-3
        assert np.all(np.abs(gain - work) <= 1e-2 * np.abs(work) + 1e-18), (gain, work)


@FAST
@given(data=st.data())
def test_momentum_balance_with_both_ends_free(data: st.DataObject) -> None:
    """Force drive with a free far end: both ends carry only the constant preload force, so the
    total momentum at the end equals the impulse of the applied force pulse."""
    chain = data.draw(chains(far_end="free"))
    amp = data.draw(st.floats(0.05, 2.0)) * chain.f0_N
    rate = 1e6
    n = data.draw(st.integers(20, 200))
    pulse = np.sin(np.linspace(0.0, np.pi, n))  # a one-signed pulse, n samples at 1 MS/s
    direction = data.draw(st.sampled_from(["ltr", "rtl"]))
    drive = dem.Drive(direction, "force", amp, waveform=(pulse, rate), delay_s=1e-5)  # type: ignore[arg-type]
    res = dem.simulate(chain, [drive], duration_s=1e-3, sample_rate_Hz=RATE)
    impulse = amp * np.sum(0.5 * (pulse[1:] + pulse[:-1])) / rate  # exact for the linear table
    sign = 1.0 if direction == "ltr" else -1.0
    p_end = float(res.meta["momentum_end_kg_m_s"][0])
    assert abs(p_end - sign * impulse) <= 2e-3 * impulse, (p_end, impulse)


@FAST
@given(data=st.data())
def test_batch_composition_does_not_change_a_drive(data: st.DataObject) -> None:
    """A drive simulated alone equals the same drive inside a mixed batch (other directions,
    kinds and lane widths)."""
    chain = data.draw(chains())
    drive = data.draw(drives(chain))
    others = [data.draw(drives(chain)) for _ in range(data.draw(st.integers(3, 6)))]
    pos = data.draw(st.integers(0, len(others)))
    batch = [*others[:pos], drive, *others[pos:]]
    alone = dem.simulate(chain, [drive], duration_s=1e-3, sample_rate_Hz=RATE)
    mixed = dem.simulate(chain, batch, duration_s=1e-3, sample_rate_Hz=RATE)
    v0, v1 = alone.velocity[0], mixed.velocity[pos]
    scale = max(float(np.abs(v0).max()), 1e-300)
    assert float(np.abs(v1 - v0).max()) <= 1e-12 * scale
    assert mixed.meta["energy_gain_J"][pos] == alone.meta["energy_gain_J"][0] or np.isclose(
        mixed.meta["energy_gain_J"][pos], alone.meta["energy_gain_J"][0], rtol=1e-12, atol=0
    )
