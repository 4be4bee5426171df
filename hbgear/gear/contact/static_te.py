r"""Loaded static transmission error and load sharing (MODEL.md section 9).

At mesh phase ``s`` the pairs ``j = 0, 1, ...`` sit at ``xi_p,j = x_A + p_b (s + j)`` and are in
contact while ``s + j < Gamma`` (as in ``GearPairModel.pair_positions``). Pair ``j`` has
stiffness ``k_j = k_pair(xi_p,j - x_A)`` and closes at the gap ``g_j = eps + e_j`` (unloaded
STE plus composite profile deviation). The quasi-static transmission error ``delta_s`` solves

    sum_j k_j max(delta_s - g_j, 0) = N.

The left side is continuous, piecewise linear and increasing in ``delta_s``, so with the gaps
sorted, ``g_(1) <= g_(2) <= ...``, and ``m`` the number of pairs loaded,
``delta_s = (N + sum_{i<=m} k_(i) g_(i)) / sum_{i<=m} k_(i)``, where ``m`` is the number of
sorted gaps at which the force needed to reach them, ``sum_{l<i} k_(l) (g_(i) - g_(l))``, is
still below ``N``. That is exact (no iteration, no tolerance) and vectorised over phases and
loads. The pair loads are ``F_j = k_j max(delta_s - g_j, 0)`` and the effective mesh stiffness
``dN/d delta_s = sum of k_j over the pairs carrying load``.

:func:`loaded_te_table` evaluates this at a list of pinion torques ``T_p`` (``N = T_p / R_bp``),
each with its own stiffness model if the stiffness depends on the load (ISO 6336's low-load
factor), with the harmonic unloaded STE ``eps(s)`` of the config.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..geometry import GearPair
from .profile import ProfileModification
from .stiffness import RectangularMeshStiffness, TablePairStiffness

__all__ = [
    "DEFAULT_PHASES",
    "LoadedTE",
    "StaticTE",
    "harris_map",
    "loaded_te_table",
    "pair_positions",
    "pair_stiffness_max",
    "slot_stiffness",
    "solve_static_contact",
    "static_transmission_error",
    "unloaded_ste",
]

#: Mesh phases sampled per mesh period by default (uniform, from 0).
DEFAULT_PHASES = 720


def pair_positions(pair: GearPair, s, slots: int | None = None, xp=np):
    """``(xi_p, in_contact)`` of the pair slots at mesh phases `s`, each ``(slots,) + s.shape``.

    ``xi_p,j = x_A + p_b (s + j)`` [m] from ``T_1``; ``in_contact`` while ``s + j < Gamma``.
    `slots` defaults to ``ceil(Gamma)``, enough for any contact ratio.
    """
    s = xp.asarray(s, dtype=float)
    slots = pair.pair_slots if slots is None else slots
    age = s[None] + xp.reshape(xp.arange(slots, dtype=s.dtype), (slots,) + (1,) * s.ndim)
    return pair.contact_start_m + pair.base_pitch_m * age, age < pair.contact_ratio


def slot_stiffness(pair_stiffness, pair: GearPair, xi_p, in_contact, xp=np):
    """``k_j`` [N/m] of the slots at `xi_p` (from ``T_1``), the shape of `xi_p`.

    A single-pair model is evaluated at ``xi_p - x_A``; the mesh-level
    :class:`~.stiffness.RectangularMeshStiffness` shares ``k(s)`` among the pairs `in_contact`.
    """
    if isinstance(pair_stiffness, RectangularMeshStiffness):
        return pair_stiffness.slot_stiffness(in_contact, xp)
    return pair_stiffness.stiffness(xp.asarray(xi_p) - pair.contact_start_m, xp)


def unloaded_ste(phase, amplitude_m=(), phase_rad=(), xp=np):
    """Unloaded STE ``eps(s) = sum_n A_n cos(2 pi n s + phi_n)`` [m], mesh orders ``n = 1, 2, ...``
    (as ``GearPairModel.static_transmission_error``), the shape of `phase`."""
    phase = xp.asarray(phase, dtype=float)
    eps = 0.0 * phase
    for order, (amplitude, angle) in enumerate(zip(amplitude_m, phase_rad, strict=True), start=1):
        eps = eps + amplitude * xp.cos(2 * np.pi * order * phase + angle)
    return eps


def pair_stiffness_max(pair_stiffness, pair: GearPair) -> float:
    """Largest single-pair stiffness over the path of contact [N/m].

    Sampled at 1001 uniform points of ``[0, x_E - x_A]`` (which hold the mid-path maximum of the
    ISO parabola) and at a table's nodes inside the path (where a piecewise-linear table has its
    maximum), so it is exact for the models here; for the rectangular model it is the largest
    share, ``max(k_max/2, k_min)``.
    """
    if isinstance(pair_stiffness, RectangularMeshStiffness):
        return pair_stiffness.pair_max_N_per_m
    path = pair.contact_end_m - pair.contact_start_m
    xi = np.linspace(0.0, path, 1001)
    if isinstance(pair_stiffness, TablePairStiffness):
        nodes = np.asarray(pair_stiffness.positions_m)
        xi = np.concatenate([xi, nodes[(nodes >= 0.0) & (nodes <= path)]])
    return float(np.max(pair_stiffness.stiffness(xi, np)))


def solve_static_contact(stiffness, gap, in_contact, load, xp=np):
    """Exact ``delta`` of ``sum_j k_j max(delta - g_j, 0) = N`` (module docstring).

    **Arguments:** `stiffness` ``k_j`` [N/m] (> 0 where in contact), `gap` ``g_j`` [m] and
    `in_contact` (bool), each ``(slots,) + shape``; `load` ``N >= 0`` [N], broadcastable
    against ``shape`` (a leading load axis in front of the phase axes: ``load[:, None]``).
    At least one pair must be in contact everywhere.

    **Returns:** ``(delta, pair_loads, mesh_stiffness)``: ``delta`` [m] of the broadcast
    shape, ``pair_loads`` [N] with the slot axis in front, and ``sum k_j`` of the loaded pairs
    [N/m] (for ``N = 0``: the smallest gap, zero loads and the stiffness of the pairs at it).
    """
    load = xp.asarray(load, dtype=float)
    gap, stiffness, in_contact = (xp.asarray(a) for a in (gap, stiffness, in_contact))
    shape = np.broadcast_shapes(gap.shape[1:], load.shape)
    lead = (gap.shape[0],) + (1,) * (len(shape) - (gap.ndim - 1))
    gap, stiffness, in_contact = (xp.broadcast_to(xp.reshape(a, lead + a.shape[1:]), gap.shape[:1] + shape)
                                  for a in (gap, stiffness, in_contact))
    g = xp.where(in_contact, gap, math.inf)
    k = xp.where(in_contact, stiffness, 0.0)
    order = xp.argsort(g, axis=0)
    g_sorted = xp.take_along_axis(g, order, axis=0)
    k_sorted = xp.take_along_axis(k, order, axis=0)
    finite = xp.isfinite(g_sorted)
    g_finite = xp.where(finite, g_sorted, 0.0)  # k is 0 where g is inf: no inf * 0
    kg_sorted = k_sorted * g_finite
    k_total = xp.cumsum(k_sorted, axis=0)
    kg_total = xp.cumsum(kg_sorted, axis=0)
    # force needed to close the sorted gap i with the pairs before it: sum_{l<i} k_l (g_i - g_l)
    to_reach = xp.where(finite, g_finite * (k_total - k_sorted) - (kg_total - kg_sorted), math.inf)
    loaded = xp.maximum(xp.sum(to_reach < load[None], axis=0), 1)
    last = (loaded - 1)[None]
    delta = (load + xp.take_along_axis(kg_total, last, axis=0)[0]) / xp.take_along_axis(k_total, last, axis=0)[0]
    closure = xp.where(in_contact, delta[None] - gap, 0.0)
    pair_loads = stiffness * xp.maximum(closure, 0.0)
    carrying = in_contact & (closure >= 0.0)
    return delta, pair_loads, xp.sum(xp.where(carrying, stiffness, 0.0), axis=0)


class StaticTE(NamedTuple):
    """Loaded static transmission error over a mesh period (SI); ``L`` load axes, ``n`` phases."""

    phase: np.ndarray  #: mesh phases ``s`` ``(n,)``
    position_m: np.ndarray  #: ``xi_p,j`` from ``T_1`` ``(slots, n)``
    delta_m: np.ndarray  #: loaded TE ``delta_s`` ``L + (n,)``
    pair_loads_N: np.ndarray  #: ``F_j`` ``(slots,) + L + (n,)``
    mesh_stiffness_N_per_m: np.ndarray  #: ``dN/d delta_s`` ``L + (n,)``
    p2p_m: np.ndarray  #: peak-to-peak of ``delta_s`` over the phases ``L``
    mean_m: np.ndarray  #: mean of ``delta_s`` over the phases ``L``


def static_transmission_error(
    pair: GearPair,
    pair_stiffness,
    load_N,
    *,
    modification: ProfileModification | None = None,
    phases=None,
    unloaded_ste_m=0.0,
) -> StaticTE:
    """Loaded static TE of `pair` under the normal load(s) `load_N` (module docstring).

    **Arguments:**

    - `pair_stiffness`: a pair stiffness model (``.stiffness(xi, xp)``, ``xi`` from ``x_A``), or
      the mesh-level :class:`~.stiffness.RectangularMeshStiffness` (see :func:`slot_stiffness`).
    - `load_N`: normal load ``N = T_p / R_bp`` [N], a scalar or a 1-D array of loads.
    - `modification`: profile relief (:class:`~.profile.ProfileModification`), default none.
    - `phases`: mesh phases in [0, 1); default :data:`DEFAULT_PHASES` uniform. The mean and peak-to-peak are taken
      over these samples, so use a uniform grid that contains the phases of interest.
    - `unloaded_ste_m`: ``eps(s)`` [m], a scalar or an array of the shape of `phases`.

    **Returns:** :class:`StaticTE` (numpy).
    """
    phase = np.arange(DEFAULT_PHASES) / DEFAULT_PHASES if phases is None else np.asarray(phases, dtype=float)
    xi_p, in_contact = pair_positions(pair, phase)
    stiffness = slot_stiffness(pair_stiffness, pair, xi_p, in_contact)
    deviation = 0.0 if modification is None else modification.deviation(pair, xi_p, np)
    gap = np.broadcast_to(np.asarray(unloaded_ste_m) + deviation, xi_p.shape)
    load = np.asarray(load_N, dtype=float)
    delta, loads, k_mesh = solve_static_contact(stiffness, gap, in_contact, load[..., None], np)
    return StaticTE(phase, xi_p, delta, loads, k_mesh, np.ptp(delta, axis=-1), np.mean(delta, axis=-1))


def harris_map(pair: GearPair, pair_stiffness, loads_N, **options) -> np.ndarray:
    """Peak-to-peak loaded static TE [m] at each normal load in `loads_N` (the Harris map).

    `options` as for :func:`static_transmission_error`; all loads are solved at once.
    """
    return static_transmission_error(pair, pair_stiffness, np.asarray(loads_N, dtype=float), **options).p2p_m


class LoadedTE(NamedTuple):
    """Loaded static TE at ``L`` pinion torques over ``n`` mesh phases, ``J`` pair slots (SI)."""

    torque_pinion_Nm: np.ndarray  #: ``T_p`` ``(L,)``
    load_N: np.ndarray  #: ``N = T_p / R_bp`` ``(L,)``
    phase: np.ndarray  #: mesh phases ``s`` ``(n,)``
    position_m: np.ndarray  #: ``xi_p,j - x_A``, from the start of active contact ``(J, n)``
    in_contact: np.ndarray  #: ``s + j < Gamma`` ``(J, n)``
    delta_m: np.ndarray  #: loaded TE ``delta_s`` ``(L, n)``
    pair_loads_N: np.ndarray  #: ``F_j`` ``(L, J, n)``
    pair_stiffness_N_per_m: np.ndarray  #: ``k_j`` (0 out of contact) ``(L, J, n)``
    mesh_stiffness_N_per_m: np.ndarray  #: ``dN/d delta_s`` ``(L, n)``
    p2p_m: np.ndarray  #: peak-to-peak of ``delta_s`` over the phases ``(L,)``
    mean_m: np.ndarray  #: mean of ``delta_s`` over the phases ``(L,)``
    mesh_stiffness_mean_N_per_m: np.ndarray  #: mean of ``dN/d delta_s`` over the phases ``(L,)``
    pair_stiffness_max_N_per_m: np.ndarray  #: :func:`pair_stiffness_max` of each model ``(L,)``


def loaded_te_table(
    pair: GearPair,
    pair_stiffness,
    torques_Nm,
    *,
    modification: ProfileModification | None = None,
    phases=None,
    ste_amplitude_m=(),
    ste_phase_rad=(),
) -> LoadedTE:
    """Loaded static TE of `pair` at each pinion torque (module docstring), as arrays.

    **Arguments:**

    - `pair_stiffness`: one stiffness model for every torque (as for
      :func:`static_transmission_error`), or a list of one model per torque.
    - `torques_Nm`: pinion torques ``T_p`` [N m] (> 0); the normal load is ``N = T_p / R_bp``.
    - `modification`: profile relief, default none. `phases`: as for
      :func:`static_transmission_error`.
    - `ste_amplitude_m`, `ste_phase_rad`: the unloaded STE per mesh order (:func:`unloaded_ste`).

    **Returns:** :class:`LoadedTE`.
    """
    torques = np.atleast_1d(np.asarray(torques_Nm, dtype=float))
    models = list(pair_stiffness) if isinstance(pair_stiffness, (list, tuple)) else [pair_stiffness] * torques.size
    if len(models) != torques.size:
        raise ValueError(f"{len(models)} stiffness models for {torques.size} torques")
    phase = np.arange(DEFAULT_PHASES) / DEFAULT_PHASES if phases is None else np.asarray(phases, dtype=float)
    eps = unloaded_ste(phase, ste_amplitude_m, ste_phase_rad)
    xi_p, in_contact = pair_positions(pair, phase)
    loads = torques / pair.base_radius_pinion_m
    runs = [static_transmission_error(pair, model, load, modification=modification, phases=phase, unloaded_ste_m=eps)
            for model, load in zip(models, loads)]
    k_slots = np.stack([np.where(in_contact, slot_stiffness(model, pair, xi_p, in_contact), 0.0) for model in models])
    k_mesh = np.stack([run.mesh_stiffness_N_per_m for run in runs])
    return LoadedTE(
        torque_pinion_Nm=torques,
        load_N=loads,
        phase=phase,
        position_m=xi_p - pair.contact_start_m,
        in_contact=in_contact,
        delta_m=np.stack([run.delta_m for run in runs]),
        pair_loads_N=np.stack([run.pair_loads_N for run in runs]),
        pair_stiffness_N_per_m=k_slots,
        mesh_stiffness_N_per_m=k_mesh,
        p2p_m=np.array([run.p2p_m for run in runs]),
        mean_m=np.array([run.mean_m for run in runs]),
        mesh_stiffness_mean_N_per_m=np.mean(k_mesh, axis=-1),
        pair_stiffness_max_N_per_m=np.array([pair_stiffness_max(model, pair) for model in models]),
    )
