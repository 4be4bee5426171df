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
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..geometry import GearPair
from .profile import ProfileModification

__all__ = ["StaticTE", "harris_map", "pair_positions", "solve_static_contact", "static_transmission_error"]


def pair_positions(pair: GearPair, s, slots: int | None = None, xp=np):
    """``(xi_p, in_contact)`` of the pair slots at mesh phases `s`, each ``(slots,) + s.shape``.

    ``xi_p,j = x_A + p_b (s + j)`` [m] from ``T_1``; ``in_contact`` while ``s + j < Gamma``.
    `slots` defaults to ``ceil(Gamma)``, enough for any contact ratio.
    """
    s = xp.asarray(s, dtype=float)
    slots = pair.pair_slots if slots is None else slots
    age = s[None] + xp.reshape(xp.arange(slots, dtype=s.dtype), (slots,) + (1,) * s.ndim)
    return pair.contact_start_m + pair.base_pitch_m * age, age < pair.contact_ratio


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

    - `pair_stiffness`: a pair stiffness model (``.stiffness(xi, xp)``, ``xi`` from ``x_A``).
    - `load_N`: normal load ``N = T_p / R_bp`` [N], a scalar or a 1-D array of loads.
    - `modification`: profile relief (:class:`~.profile.ProfileModification`), default none.
    - `phases`: mesh phases in [0, 1); default 720 uniform. The mean and peak-to-peak are taken
      over these samples, so use a uniform grid that contains the phases of interest.
    - `unloaded_ste_m`: ``eps(s)`` [m], a scalar or an array of the shape of `phases`.

    **Returns:** :class:`StaticTE` (numpy).
    """
    phase = np.arange(720) / 720 if phases is None else np.asarray(phases, dtype=float)
    xi_p, in_contact = pair_positions(pair, phase)
    stiffness = pair_stiffness.stiffness(xi_p - pair.contact_start_m, np)
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
