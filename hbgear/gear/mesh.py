r"""The tooth mesh of the gear pair: its contact force and what the friction needs of it.

Two meshes behind one interface, the ``mesh`` field of :class:`~hbgear.gear.model.GearPairModel`:

- :class:`RectangularMesh` (the default): the paper's mesh-level ``k(t)``, a rectangular pulse
  ``k_max`` / ``k_min`` (MODEL.md sections 2 and 4), shared equally by the pairs in contact,
  ``F_mesh = k(s) g(x) + c(s) x'`` with the backlash dead zone ``g``. Its numbers are fields of
  the model (``k_max_N_per_m``, ``k_min_N_per_m``, ``damping_model``), so it holds none.
- :class:`PairContactMesh`: per-pair contact (MODEL.md section 9). Pair ``j`` at
  ``xi_p,j = x_A + p_b (s + j)`` has the single-pair stiffness ``k_j = k_pair(xi_p,j - x_A)``,
  the composite relief ``e_j = e_p(xi_p,j) + e_g(L - xi_p,j)`` and the damper
  ``c_j = c k_j / k_mean``; the load shares emerge.

**The interface.** Every method takes the model first (for the geometry, the load ``N``, the
damping ``c = 2 zeta sqrt(k_mean m_e)`` and the backlash it holds); ``x = delta - eps`` and
``x' = delta' - eps'`` are the DTE less the unloaded STE, ``w_m`` the mesh frequency [rad/s],
``xp`` ``numpy`` or ``jax.numpy``. The mesh sees nothing else of the state: the coordinates, the
speeds and the friction stay with the model.

- ``force(model, s, x, x', w_m, xp)``: ``F_mesh`` [N]; ``pairs(...)``: :class:`PairContact`
  (per-pair force ``F_j`` and which flank of each pair touches), shapes ``(PAIR_SLOTS,) + s.shape``.
- ``stiffness``, ``damping``: the mesh-level ``k(s)`` [N/m], ``c(s)`` [N s/m] (per pair: the sums
  over the pairs of the path of contact); ``k_mean(model)`` [N/m].
- ``static_deflection(model, s, xp)``: ``D(s) = delta_s - eps`` [m] of the loaded static TE,
  ``static_loads(model, s, xp)``: ``(shares, F_j,s)``, the quasi-static per-pair loads at ``N``
  (formulation A's normal loads); ``mean_compliance``, ``compliance_fluctuation``: ``<D>/N``
  and ``(D(s) - <D>)/N`` [m/N] (LTI's loaded STE).
- ``breakpoints(model, xp)`` (candidates, may be traced) and ``phase_breakpoints(model)``
  (numpy, sorted): pair entry and exit, pitch crossings, and for per-pair contact the relief
  starts and the table's nodes inside the path.
- ``is_linear(model)``: ``F_mesh`` is affine in ``(x, x')``; ``piecewise_constant``: ``k(s)``,
  ``c(s)`` are constant between the breakpoints; ``equal_shares``: the static loads are
  ``N / n(s)`` (the closed-form wind-up applies); ``closed()``: the mesh with every pair of the
  path held in contact (the linear equivalent along solutions that keep them in contact).
- ``contact_gap(model, s, x, formulation)``, ``compressive_force(model, s, x, x', w_m)`` (numpy):
  what must stay positive along a solution for the linear equivalent to hold
  (:func:`hbgear.gear.system.linear_equivalent`).

**Backlash and the DTE in the per-pair mesh.** ``delta`` keeps the meaning of MODEL.md section 4
(the raw DTE, zero in the middle of the backlash ``2b``), so the rectangular and the per-pair
models share their coordinates and their static states: the drive flank of pair ``j`` closes at
``x > b + e_j`` and carries ``k_j (x - b - e_j) + c_j (x' - e_j')``, the back flank (mirror
geometry at the same phase, unrelieved, the drive flank's ``k_j``) closes at ``x < -b`` and carries
``k_j (x + b) + c_j x'``; an open pair carries nothing, its damper included. This is section 9
with its ``delta`` measured from the drive flank's contact, ``delta_9 = delta - b`` (there the
drive flank closes at ``delta_9 - eps - e_j > 0`` and the back flank at ``delta_9 - eps < -2b``).
Without backlash (``b = 0``) the back flank closes at ``x < 0``: without relief every pair of the
path is always in contact on one flank or the other, ``F_mesh = k(s) x + c(s) x'``, which is the
rectangular model's "teeth that never separate" -- linear, and with ``k_pair = k_1`` exactly the
rectangular model with ``k_max = 2 k_1``, ``k_min = k_1`` and proportional damping. The
rectangular model's damper keeps acting in the dead zone (section 4); the per-pair dampers do
not (section 9).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, NamedTuple

import numpy as np
from jax.tree_util import register_dataclass

from .contact.profile import ProfileModification
from .contact.static_te import solve_static_contact
from .contact.stiffness import ConstantPairStiffness, TablePairStiffness

__all__ = ["PAIR_SLOTS", "PairContact", "PairContactMesh", "RectangularMesh"]

#: Pair slots tracked in a mesh period; enough for any contact ratio below 2.
PAIR_SLOTS = 2

#: Breakpoints closer than this (in mesh phase) are one (a table node at the end of the path and
#: the pair exit, rounding).
_SAME_PHASE = 1e-12


class PairContact(NamedTuple):
    """Per-pair contact at phases ``s``; each array ``(PAIR_SLOTS,) + s.shape``.

    **Fields:** `force` ``F_j`` [N] (positive on the drive flank, negative on the back flank);
    `drive`, `back`: 1.0 where pair ``j``'s drive / back flank is in contact, else 0.0 (for a mesh
    whose pairs cannot separate, `drive` is 1 on the path of contact and `back` 0).
    """

    force: Any
    drive: Any
    back: Any


def _sorted_phases(candidates) -> np.ndarray:
    """Sorted phases in [0, 1) of `candidates` (mod 1), with near-duplicates merged."""
    phases = np.sort(np.mod(np.asarray(candidates, dtype=float), 1.0))
    phases = np.where(phases > 1.0 - _SAME_PHASE, 0.0, phases)
    phases = np.sort(phases)
    keep = np.concatenate([[True], np.diff(phases) > _SAME_PHASE])
    return phases[keep]


def _half_backlash(model):
    """``b`` [m]: half the backlash with ``contact = "backlash"``, else 0."""
    return 0.5 * model.backlash_m if model.contact == "backlash" else 0.0 * model.backlash_m


@register_dataclass
@dataclass(frozen=True)
class RectangularMesh:
    """The paper's rectangular-pulse mesh stiffness with equal load sharing (MODEL.md sections 2, 4).

    ``k(s) = k_max`` for ``s < Gamma - 1`` (two pairs), ``k_min`` after; ``c(s) = c`` or
    ``c k(s) / k_mean`` (``damping_model``); ``F_mesh = k(s) g(x) + c(s) x'``, ``g`` the identity
    or the backlash dead zone of half-width ``b``; pair ``j`` carries ``sigma_j F_mesh`` with the
    equal shares ``sigma_j`` of :meth:`GearPairModel.pair_positions`. All numbers are the model's.
    """

    per_pair = False
    piecewise_constant = True
    equal_shares = True

    def closed(self) -> RectangularMesh:
        return self

    def is_linear(self, model) -> bool:
        return model.contact == "linear"

    def k_mean(self, model):
        """``k_mean = k_max (Gamma - 1) + k_min (2 - Gamma)`` [N/m]."""
        g = model.contact_ratio
        return model.k_max_N_per_m * (g - 1.0) + model.k_min_N_per_m * (2.0 - g)

    def stiffness(self, model, s, xp=np):
        """Rectangular-pulse ``k(s)`` (Eq. 14) [N/m]."""
        return xp.where(s < model.contact_ratio - 1.0, model.k_max_N_per_m, model.k_min_N_per_m)

    def damping(self, model, s, xp=np):
        """``c(s)`` [N s/m]: constant, or proportional to ``k(s)``."""
        c = model.mesh_damping_Ns_per_m
        if model.damping_model == "proportional":
            return c * self.stiffness(model, s, xp) / model.k_mean_N_per_m
        return c + 0.0 * s

    def _dead_zone(self, model, x, xp=np):
        """``g(x)``: identity, or the backlash dead zone of half-width ``b`` [m]."""
        if model.contact == "linear":
            return x
        b = 0.5 * model.backlash_m
        return xp.where(x > b, x - b, xp.where(x < -b, x + b, 0.0 * x))

    def force(self, model, s, x, xd, omega_mesh, xp=np):
        """``F_mesh = k(s) g(x) + c(s) x'`` [N]."""
        return self.stiffness(model, s, xp) * self._dead_zone(model, x, xp) + self.damping(model, s, xp) * xd

    def pairs(self, model, s, x, xd, omega_mesh, xp=np) -> PairContact:
        """``F_j = sigma_j F_mesh``; the drive flank in contact always without backlash, else while
        ``x > b``, the back flank while ``x < -b`` (MODEL.md sections 4, 11)."""
        sigma = model.pair_positions(s, xp)[3]
        force = sigma * self.force(model, s, x, xd, omega_mesh, xp)[None]
        if model.contact == "linear":
            one = 1.0 + 0.0 * x
            drive, back = one, 0.0 * one
        else:
            b = 0.5 * model.backlash_m
            drive, back = xp.where(x > b, 1.0, 0.0), xp.where(x < -b, 1.0, 0.0)
        zero = 0.0 * sigma
        return PairContact(force, drive[None] + zero, back[None] + zero)

    def static_loads(self, model, s, xp=np):
        """``(sigma_j, sigma_j N)``: equal shares of the quasi-static load ``N``."""
        sigma = model.pair_positions(s, xp)[3]
        return sigma, sigma * model.normal_load_N

    def static_deflection(self, model, s, xp=np):
        """``D(s) = N / k(s)`` [m]."""
        return model.normal_load_N / self.stiffness(model, s, xp)

    def mean_compliance(self, model, xp=np):
        """``<1/k> = (Gamma - 1)/k_max + (2 - Gamma)/k_min`` [m/N]."""
        g = model.contact_ratio
        return (g - 1.0) / model.k_max_N_per_m + (2.0 - g) / model.k_min_N_per_m

    def compliance_fluctuation(self, model, s, xp=np):
        """``1/k(s) - <1/k>`` [m/N]."""
        return 1.0 / self.stiffness(model, s, xp) - self.mean_compliance(model, xp)

    def breakpoints(self, model, xp=np):
        """Pair exit ``Gamma - 1`` and the pitch crossings ``t_b``, ``t_b - 1`` (traced-friendly;
        entry is phase 0, always a candidate of the engine)."""
        tb = (model.pitch_point_m - model.contact_start_m) / model.base_pitch_m
        return xp.stack([xp.asarray(model.contact_ratio - 1.0), tb, tb - 1.0])

    def phase_breakpoints(self, model) -> np.ndarray:
        """Sorted phases in [0, 1): entry, exit, the pitch crossings of the slots in contact then."""
        g = float(model.contact_ratio)
        tb = (model.pitch_point_m - float(model.contact_start_m)) / float(model.base_pitch_m)
        points = {0.0, g - 1.0}
        for slot in range(PAIR_SLOTS):
            if 0.0 <= tb - slot < 1.0 and tb < g:
                points.add(tb - slot)
        return np.array(sorted(points))

    def contact_gap(self, model, s, x, formulation: str) -> np.ndarray:
        """``x - b`` (formulation B: the drive flank must stay closed) or ``|x| - b`` (A: either flank)."""
        gap = x if formulation == "B" else np.abs(x)
        return gap - 0.5 * float(model.backlash_m)

    def contact_events(self, model, s, x, xp=np):
        """``(x - b, x + b)``: where the dead zone's flanks close (``None`` without backlash)."""
        if model.contact == "linear":
            return None
        b = 0.5 * model.backlash_m
        return xp.stack([x - b, x + b])

    def compressive_force(self, model, s, x, xd, omega_mesh) -> np.ndarray:
        """``F_mesh`` (formulation B's loads are affine while it stays positive)."""
        return np.asarray(self.force(model, s, x, xd, omega_mesh, np))


class _Path(NamedTuple):
    """The path of contact of a model, in the form the profile modification reads (may be traced)."""

    line_of_action_m: Any
    contact_start_m: Any
    contact_end_m: Any


def _path(model) -> _Path:
    start = model.contact_start_m
    return _Path(model.line_of_action_m, start, start + model.contact_ratio * model.base_pitch_m)


@register_dataclass
@dataclass(frozen=True)
class PairContactMesh:
    r"""Per-pair tooth contact with a single-pair stiffness along the path and profile relief.

    Pair ``j`` in the path (``s + j < Gamma``): ``k_j = k_pair(xi_p,j - x_A)``, ``c_j = c k_j / k_mean``,
    ``e_j = e_p(xi_p,j) + e_g(L - xi_p,j)``, ``e_j' = (de_j/dxi) R_bp Omega_p``; with ``b`` half the
    backlash (0 without)::

        F_j = k_j (x - b - e_j) + c_j (x' - e_j')   while x - b - e_j > 0  (drive flank)
            = k_j (x + b) + c_j x'                  while x + b < 0        (back flank)
            = 0                                      otherwise

    and ``F_mesh = sum_j F_j`` (module docstring: why ``delta`` is measured this way). The
    quasi-static state at the load ``N`` solves ``sum_j k_j max(D - e_j, 0) = N`` exactly
    (:func:`~hbgear.gear.contact.static_te.solve_static_contact`): ``delta_s = eps + D (+ b)``, and
    the static pair loads ``k_j max(D - e_j, 0)`` are formulation A's normal loads.

    **Arguments:** `k_mean_N_per_m`: the mesh-period mean of ``sum_j k_pair(xi_j)`` over the pairs of
    the path (a property of the teeth; :meth:`build` computes it); `pair_stiffness`: a single-pair model
    with ``stiffness(xi, xp)``, ``xi`` from ``x_A`` (:class:`~hbgear.gear.contact.ConstantPairStiffness`,
    :class:`~hbgear.gear.contact.TablePairStiffness`, :class:`~hbgear.gear.contact.Iso6336PairStiffness`);
    `modification`: the :class:`~hbgear.gear.contact.ProfileModification`; `closed`: hold every pair
    of the path in contact on the drive flank (``F_j = k_j (x - b - e_j) + c_j (x' - e_j')`` always:
    the linear equivalent along solutions that keep every pair loaded). The quasi-static state and
    loads are those of the real contact in either case. `pair_stiffness` and `modification` are
    static (hashable, part of the pytree's structure), ``k_mean`` is data.
    """

    k_mean_N_per_m: float
    pair_stiffness: Any = field(default=None, metadata=dict(static=True))
    modification: ProfileModification = field(default=ProfileModification(), metadata=dict(static=True))
    closed_contact: bool = field(default=False, metadata=dict(static=True))

    per_pair = True

    @classmethod
    def build(cls, stiffness, modification: ProfileModification, model) -> PairContactMesh:
        """The mesh of `stiffness` and `modification` on the path of `model` (a
        :class:`~hbgear.gear.model.GearPairModel`, concrete), with its ``k_mean`` by Gauss-Legendre
        quadrature between the breakpoints (exact for the table's and the parabola's polynomial pieces)."""
        from ..engine.quadrature import mesh_period_rule

        mesh = cls(1.0, stiffness, modification)
        s, w = mesh_period_rule(mesh.phase_breakpoints(model), 8)
        k_mean = float(np.sum(w * mesh.stiffness(model, s)))
        return replace(mesh, k_mean_N_per_m=k_mean)

    @property
    def piecewise_constant(self) -> bool:
        """A constant pair stiffness: ``k(s)``, ``c(s)`` are constant between entry and exit."""
        return isinstance(self.pair_stiffness, ConstantPairStiffness)

    @property
    def equal_shares(self) -> bool:
        """Constant pair stiffness and no relief: the static loads are ``N / n(s)``."""
        return self.piecewise_constant and self.modification.is_zero

    def closed(self) -> PairContactMesh:
        return replace(self, closed_contact=True)

    def is_linear(self, model) -> bool:
        """Held closed, or without relief and without backlash (no pair can separate)."""
        return self.closed_contact or (self.modification.is_zero and model.contact == "linear")

    def k_mean(self, model):
        return self.k_mean_N_per_m

    # -- the pairs -------------------------------------------------------------------------------
    def _slots(self, model, s, xp=np):
        """``(in_path, k_j, e_j, de_j/dxi)`` of the slots, each ``(PAIR_SLOTS,) + s.shape``."""
        xi_p, _, in_path, _ = model.pair_positions(s, xp)
        k = in_path * self.pair_stiffness.stiffness(xi_p - model.contact_start_m, xp)
        path = _path(model)
        return in_path, k, self.modification.deviation(path, xi_p, xp), self.modification.slope(path, xi_p, xp)

    def stiffness(self, model, s, xp=np):
        """``k(s) = sum_j k_j`` over the pairs of the path [N/m]."""
        return xp.sum(self._slots(model, s, xp)[1], axis=0)

    def damping(self, model, s, xp=np):
        """``c(s) = c k(s) / k_mean`` [N s/m]."""
        return model.mesh_damping_Ns_per_m * self.stiffness(model, s, xp) / self.k_mean_N_per_m

    def pairs(self, model, s, x, xd, omega_mesh, xp=np) -> PairContact:
        """Per-pair forces and contact flags (class docstring)."""
        in_path, k, e, slope = self._slots(model, s, xp)
        c = model.mesh_damping_Ns_per_m * k / self.k_mean_N_per_m
        rate = slope * model.base_pitch_m * omega_mesh / (2.0 * math.pi)  # de_j/dt, dxi/dt = p_b w_m / 2 pi
        b = _half_backlash(model)
        x, xd = x[None], xd[None]
        closure = x - b - e
        if self.is_linear(model):
            return PairContact(k * closure + c * (xd - rate), in_path, 0.0 * in_path)
        drive = in_path * xp.where(closure > 0.0, 1.0, 0.0)
        back = in_path * xp.where(x + b < 0.0, 1.0, 0.0)
        force = drive * (k * closure + c * (xd - rate)) + back * (k * (x + b) + c * xd)
        return PairContact(force, drive, back)

    def contact_events(self, model, s, x, xp=np):
        """Functions of ``x`` whose zeros are the instants where a pair's contact (and with it its
        damper and its friction load) switches: ``(h_0 h_1 / d_0^2, (x + b)/d_0)``, ``d_0 = N/k_mean``,
        shape ``(2,) + x.shape``; ``None`` for a mesh whose pairs cannot separate.

        ``h_j = x - b - e_j`` is the drive-flank closure of slot ``j`` (tooth age ``s + j``). The
        slots swap teeth at ``s = 0``, so each ``h_j`` jumps there while the product does not: for
        the ages ``Gamma <= s + 1 < 2`` past the exit the relief is continued linearly from its value
        at the exit to its value at entry, which makes ``h_1(1^-) = h_0(0^+)`` (a zero of the product
        out of the path is harmless: no force jumps there). The back flank (unrelieved) closes at
        ``x = -b`` for every pair.
        """
        if self.is_linear(model):
            return None
        xi_p, _, in_path, _ = model.pair_positions(s, xp)
        path = _path(model)
        e = self.modification.deviation(path, xi_p, xp)
        entry = self.modification.deviation(path, path.contact_start_m + 0.0 * s, xp)
        exit_ = self.modification.deviation(path, path.contact_end_m + 0.0 * s, xp)
        gamma = model.contact_ratio
        beyond = exit_ + (entry - exit_) * (s + 1.0 - gamma) / (2.0 - gamma)
        e1 = xp.where(in_path[1] > 0.0, e[1], beyond)
        b = _half_backlash(model)
        d0 = model.normal_load_N / self.k_mean_N_per_m
        return xp.stack([(x - b - e[0]) * (x - b - e1) / d0 ** 2, (x + b) / d0])

    def force(self, model, s, x, xd, omega_mesh, xp=np):
        """``F_mesh = sum_j F_j`` [N]."""
        return xp.sum(self.pairs(model, s, x, xd, omega_mesh, xp).force, axis=0)

    # -- the quasi-static state ------------------------------------------------------------------
    def _static(self, model, s, xp=np):
        """``(D, F_j,s)`` of ``sum_j k_j max(D - e_j, 0) = N``."""
        in_path, k, e, _ = self._slots(model, s, xp)
        deflection, loads, _ = solve_static_contact(k, e, in_path > 0.0, model.normal_load_N, xp)
        return deflection, loads

    def static_loads(self, model, s, xp=np):
        """``(F_j,s / N, F_j,s)``: the emerging static shares and loads [N]."""
        loads = self._static(model, s, xp)[1]
        return loads / model.normal_load_N, loads

    def static_deflection(self, model, s, xp=np):
        """``D(s) = delta_s - eps`` [m]."""
        return self._static(model, s, xp)[0]

    def mean_compliance(self, model, xp=np):
        """``<D>/N`` [m/N], by Gauss-Legendre between the breakpoints (32 sub-intervals per unit phase)."""
        from ..engine.quadrature import mesh_period_rule

        s, w = mesh_period_rule(self.breakpoints(model, xp), 16, xp)
        return xp.sum(w * self.static_deflection(model, s, xp)) / model.normal_load_N

    def compliance_fluctuation(self, model, s, xp=np):
        """``(D(s) - <D>)/N`` [m/N]."""
        return self.static_deflection(model, s, xp) / model.normal_load_N - self.mean_compliance(model, xp)

    # -- where the equations switch --------------------------------------------------------------
    def _kinks(self, model):
        """Positions from ``T_1`` of the relief starts and of the table's nodes inside the path."""
        starts = self.modification.starts(_path(model))
        nodes = ()
        if isinstance(self.pair_stiffness, TablePairStiffness):
            length = float(model.contact_ratio) * float(model.base_pitch_m)
            nodes = tuple(float(model.contact_start_m) + xi for xi in self.pair_stiffness.positions_m
                          if 0.0 < xi < length)
        return starts + nodes

    def breakpoints(self, model, xp=np):
        """The rectangular mesh's candidates and the phases of :meth:`_kinks` (traced-friendly)."""
        base = RectangularMesh().breakpoints(model, xp)
        kinks = self._kinks(model)
        if not kinks:
            return base
        phases = xp.mod((xp.stack([xp.asarray(x) for x in kinks]) - model.contact_start_m) / model.base_pitch_m, 1.0)
        return xp.concatenate([base, phases])

    def phase_breakpoints(self, model) -> np.ndarray:
        """Sorted phases in [0, 1): the rectangular mesh's and those of :meth:`_kinks`."""
        kinks = (np.asarray([float(x) for x in self._kinks(model)]) - float(model.contact_start_m)) / float(
            model.base_pitch_m)
        return _sorted_phases(np.concatenate([RectangularMesh().phase_breakpoints(model), kinks]))

    # -- the linear regime -----------------------------------------------------------------------
    def contact_gap(self, model, s, x, formulation: str) -> np.ndarray:
        """Per phase, ``min_j (x - b - e_j)`` over the pairs of the path (every drive flank closed);
        formulation A also accepts ``-(x + b)`` (every back flank closed)."""
        in_path, _, e, _ = (np.asarray(a) for a in self._slots(model, s, np))
        b = float(_half_backlash(model))
        drive = np.min(np.where(in_path > 0.0, x[None] - b - e, np.inf), axis=0)
        return drive if formulation == "B" else np.maximum(drive, -(x + b))

    def compressive_force(self, model, s, x, xd, omega_mesh) -> np.ndarray:
        """``min_j F_j`` over the pairs of the path, of the mesh held closed."""
        in_path = np.asarray(model.pair_positions(s, np)[2])
        force = np.asarray(self.closed().pairs(model, s, x, xd, omega_mesh, np).force)
        return np.min(np.where(in_path > 0.0, force, np.inf), axis=0)
