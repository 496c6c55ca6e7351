"""A built chain: every cylinder's discrete element (primary mass + resonators) and the contacts."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from sim_backend.dem.beam import cylinder_modes
from sim_backend.dem.contact import hertz_beta, linear_stiffness, static_overlap
from sim_backend.dem.material import Material
from sim_backend.dem.spec import ChainSpec

__all__ = ["Chain", "build_chain", "contact_beta", "crossing_time_s", "crossing_time_upper_s"]


@dataclass(frozen=True, eq=False)
class Chain:
    """The chain in SI units (index 0 = cylinder #1).

    Attributes
    ----------
    spec: the :class:`ChainSpec` it was built from.
    n: number of cylinders N.
    n_modes: resonators per cylinder J.
    lengths_m: [N] cylinder lengths (m).
    diameter_m: cylinder diameter (m).
    f0_N: static preload F0 (N).
    beta_c: Hertz coefficient (N/m^1.5).
    delta0_m: static overlap of every contact (m).
    K_lin: linearised contact stiffness (N/m).
    mass_kg: [N] total cylinder masses (kg).
    m0_kg: [N] primary (residual) masses (kg).
    m_res_kg: [N, J] resonator masses (kg).
    k_res_N_per_m: [N, J] resonator stiffnesses (N/m).
    omega_res_rad_s: [N, J] centre-clamped angular frequencies (rad/s).
    bending_damping_ratio: modal damping ratio of every cylinder's free-free bending modes (the
        flexible modes of the contact-free block, primary mass + resonators).
    contact_damping_ratio: contact dashpot ratio, c = 2 zeta sqrt(K m0) per contact.
    far_end: "wall" or "free".
    material: the material.
    rest_overlap_m: [N+1] overlap at rest (m) of each contact (drive wall-#1, #1-#2, ...,
        #N-far wall): delta0, minus the gap where the chain file sets one (negative = open).
    """

    spec: ChainSpec
    n: int
    n_modes: int
    lengths_m: NDArray[np.float64]
    diameter_m: float
    f0_N: float
    beta_c: float
    delta0_m: float
    K_lin: float
    mass_kg: NDArray[np.float64]
    m0_kg: NDArray[np.float64]
    m_res_kg: NDArray[np.float64]
    k_res_N_per_m: NDArray[np.float64]
    omega_res_rad_s: NDArray[np.float64]
    bending_damping_ratio: float
    contact_damping_ratio: float
    far_end: str
    material: Material
    rest_overlap_m: NDArray[np.float64]

    def hunt_crossley_chi_s_per_m(self) -> NDArray[np.float64]:
        """[N+1] Hunt-Crossley factor chi = c / F0 (s/m) of each contact, so that the contact
        force is ``beta d^1.5 (1 + chi d')``; 0 where there is no dashpot (also at F0 = 0, where
        the spec requires ``contact_dashpot_ratio = 0``)."""
        dash = self.contact_dashpot_Ns_per_m()
        if self.f0_N > 0:
            return dash / self.f0_N
        return np.zeros_like(dash)

    @property
    def damped(self) -> bool:
        """True when any damping ratio (bending modes or contacts) is above 0."""
        return self.bending_damping_ratio > 0.0 or self.contact_damping_ratio > 0.0

    def block_matrices(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Each cylinder's free (J+1)-mass block, the primary and its resonators, each on a spring
        ``k_res`` to the primary: ``(stiffness [N, J+1, J+1] (N/m), mass [N, J+1] (kg))``, index
        0 the primary. Its eigenfrequencies are the block modes (``simulation.block_modes``) and
        the quasi-band onsets (``bands.quasi_bands``)."""
        N, J = self.k_res_N_per_m.shape
        k = self.k_res_N_per_m
        stiff = np.zeros((N, J + 1, J + 1))
        stiff[:, 0, 0] = k.sum(axis=1)
        stiff[:, 0, 1:] = -k
        stiff[:, 1:, 0] = -k
        stiff[:, np.arange(1, J + 1), np.arange(1, J + 1)] = k
        return stiff, np.concatenate([self.m0_kg[:, None], self.m_res_kg], axis=1)

    def contact_dashpot_Ns_per_m(self) -> NDArray[np.float64]:
        """[N+1] dashpot coefficient (N s/m) of each contact: wall-#1, #1-#2, ..., #N-wall."""
        m = np.concatenate([self.m0_kg[:1], self.m0_kg, self.m0_kg[-1:]])
        m_pair = 0.5 * (m[:-1] + m[1:])
        return 2.0 * self.contact_damping_ratio * np.sqrt(self.K_lin * m_pair)


_CACHE: dict[str, Chain] = {}


def contact_beta(spec: ChainSpec) -> float:
    """The chain's Hertz constant beta_c (N/m^1.5): the crossed cylinders' own, times the
    spec's ``contact_stiffness_factor``."""
    beta = hertz_beta(spec.diameter, spec.material.to_material(), spec.crossing_angle)
    if spec.contact_stiffness_factor != 1.0:
        beta *= spec.contact_stiffness_factor
    return beta


def crossing_time_upper_s(spec: ChainSpec) -> float:
    """An upper bound (s) of the chain's fastest contact crossing ``sqrt(min m0 / K)`` without
    its modes: the lightest cylinder's whole mass (its rigid part ``m0`` is lighter) over the
    linearised contact stiffness. Inf at a preload of 0 N (no linear wave)."""
    material = spec.material.to_material()
    factors = spec.density_factors or {}
    area = 0.25 * np.pi * spec.diameter**2
    lightest = min(
        material.density_kg_per_m3 * factors.get(i + 1, 1.0) * area * float(length)
        for i, length in enumerate(spec.lengths_m())
    )
    k = linear_stiffness(spec.preload, contact_beta(spec))
    return float(np.sqrt(lightest / k)) if k > 0 else float("inf")


def crossing_time_s(spec: ChainSpec) -> float:
    """The chain's fastest contact crossing ``sqrt(min m0 / K)`` (s): the lightest rigid mass
    over the linearised contact stiffness, :attr:`Chain.m0_kg` and :attr:`Chain.K_lin` of
    :func:`build_chain` without the other cylinders' modes where the cylinders differ in length
    only (the shortest is the lightest: a window check of 2000 Latin-hypercube chains took
    6.6 s building them whole). Inf at a preload of 0 N."""
    k = linear_stiffness(spec.preload, contact_beta(spec))
    if not k > 0:
        return float("inf")
    shortest = float(np.min(spec.lengths_m()))
    # the shortest is the lightest rigid mass for slender cylinders; a Timoshenko disk (length
    # below about 0.13 diameters) is not monotonic in length (a reviewer: 3x off at 1.75 mm of
    # 13.6 mm): those, and denser cylinders, are built whole
    if spec.density_factors or (
        spec.beam_theory != "euler-bernoulli" and shortest < 0.25 * spec.diameter
    ):
        m0 = float(np.min(build_chain(spec).m0_kg))
    else:
        (modes,) = cylinder_modes(
            [shortest], spec.diameter, [spec.material.to_material()], spec.n_modes,
            spec.beam_theory,
        )  # fmt: skip
        m0 = float(modes.residual_mass_kg)
    return float(np.sqrt(m0 / k))


def build_chain(spec: ChainSpec) -> Chain:
    """Build (and cache, keyed by the spec's content) the discrete-element chain of ``spec``."""
    key = spec.model_dump_json()
    hit = _CACHE.get(key)
    if hit is not None:
        return hit
    material = spec.material.to_material()
    lengths = spec.lengths_m()
    n = len(lengths)
    J = spec.n_modes
    mass = np.empty(n)
    m0 = np.empty(n)
    mres = np.empty((n, J))
    omega = np.empty((n, J))
    factors = spec.density_factors or {}
    materials = []
    for i in range(n):
        f = factors.get(i + 1, 1.0)
        # a denser (heavier) cylinder of the same stiffness
        materials.append(
            material
            if f == 1.0
            else dataclasses.replace(material, density_kg_per_m3=material.density_kg_per_m3 * f)
        )
    all_modes = cylinder_modes(
        [float(L) for L in lengths], spec.diameter, materials, J, spec.beam_theory
    )
    for i, modes in enumerate(all_modes):
        mass[i] = modes.mass_kg
        m0[i] = modes.residual_mass_kg
        mres[i] = modes.modal_mass_kg
        omega[i] = modes.omega_rad_s
    beta = contact_beta(spec)
    delta0 = static_overlap(spec.preload, beta)
    rest = np.full(n + 1, delta0)
    for k, g in (spec.contact_gaps or {}).items():
        rest[k] = delta0 - g
    chain = Chain(
        spec=spec,
        n=n,
        n_modes=J,
        lengths_m=lengths,
        diameter_m=spec.diameter,
        f0_N=spec.preload,
        beta_c=beta,
        delta0_m=delta0,
        K_lin=linear_stiffness(spec.preload, beta),
        mass_kg=mass,
        m0_kg=m0,
        m_res_kg=mres,
        k_res_N_per_m=mres * omega**2,
        omega_res_rad_s=omega,
        bending_damping_ratio=spec.damping.bending_mode_ratio,
        contact_damping_ratio=spec.damping.contact_dashpot_ratio,
        far_end=spec.far_end,
        material=material,
        rest_overlap_m=rest,
    )
    for arr in (lengths, mass, m0, mres, omega, chain.k_res_N_per_m, rest):
        arr.setflags(write=False)
    if len(_CACHE) > 256:
        _CACHE.clear()
    _CACHE[key] = chain
    return chain
