"""The gear pair as a periodic system of the harmonic-balance engine (:mod:`hbgear.engine.system`)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from jax.tree_util import register_dataclass

from ..engine import events
from ..engine.system import PeriodicSystem
from .model import GearPairModel

__all__ = ["GearSystem", "linear_equivalent"]


@register_dataclass
@dataclass(frozen=True)
class GearSystem(PeriodicSystem):
    """The gear pair as a periodic system in the parameter ``parameter``.

    **Arguments:** `model`: the :class:`~hbgear.gear.model.GearPairModel`; `omega_pinion`: the pinion
    speed [rad/s] used when the parameter is not the speed; `parameter`: ``"speed"`` (the
    parameter is ``Omega_p`` [rad/s]) or the name of a float field of the model
    (``"torque_pinion_Nm"``, ``"damping_ratio"``, ...).
    """

    model: GearPairModel
    omega_pinion: float = 0.0
    parameter: str = field(default="speed", metadata=dict(static=True))

    def _at(self, p):
        if self.parameter == "speed":
            return self.model, p
        if self.parameter == "mu0":
            return self.model.replace(friction=replace(self.model.friction, mu0=p)), self.omega_pinion
        return self.model.replace(**{self.parameter: p}), self.omega_pinion

    @property
    def ndof(self) -> int:
        return self.model.ndof

    @property
    def is_linear(self) -> bool:
        return self.model.is_linear

    @property
    def free_mean_dof(self):
        return 1 if self.model.boundary == "reaction" else None

    @property
    def coefficients_independent_of_parameter(self) -> bool:
        """True when the periodic stiffness and damping coefficients do not depend on ``p``.

        In a speed sweep they come from ``k(t)``, ``c(t)`` and, for formulation B with a linear
        friction part (LTV without backlash: ``sigma_j F_mesh``), the nominal friction factors:
        those depend on the speed only through a law with a velocity scale (arctan,
        Kelley--Lemanski). LTI's energy-equivalent friction damping depends on the speed.
        """
        if self.parameter != "speed":
            return False
        m = self.model
        if m.coupling == "LTI" and m.lti_friction != "excitation":
            return False  # the energy-equivalent damping follows the speed
        friction_in_coefficients = m.friction_has_linear_part and m.formulation == "B"
        return not friction_in_coefficients or m.friction.name in ("none", "coulomb")

    @property
    def forcing_affine_in_frequency(self) -> bool:
        """True when the forcing (the linear part at ``q = q' = 0``) is ``Fbar(w) + A(s) + w B(s)``.

        In a speed sweep the mesh term ``-k eps - c eps'`` is affine in ``w`` (``eps' ~ w_m``),
        the input/output torques and the spring's wind-up ``u_s(w)`` are constant in ``s``, the
        LTI impulses ``dG/dt = w_m dG/ds``; only a linear friction part with a velocity scale
        (arctan, Kelley--Lemanski in LTI/LTV) depends on the speed otherwise. Checked
        numerically by the harmonic balance.
        """
        if self.parameter != "speed":
            return False
        m = self.model
        excitation = m.friction_has_linear_part and not (m.coupling == "LTI" and m.lti_friction == "damping")
        return not excitation or m.friction.name in ("none", "coulomb")

    @property
    def forcing_mean_affine_in_frequency(self) -> bool:
        """True when, besides :attr:`forcing_affine_in_frequency`, ``Fbar(w)`` is affine in ``w``:
        the torques are constant and the mesh term's mean affine; what is not is the soft spring's
        wind-up ``u_s(w)``, which balances the mean static friction force: constant without
        friction and for Coulomb's law (the sign of the sliding velocity, proportional to the
        speed, does not change with it), a function of the speed for laws with a velocity scale.
        Checked numerically by the harmonic balance."""
        m = self.model
        return self.forcing_affine_in_frequency and (m.boundary != "spring" or m.friction.name in ("none", "coulomb"))

    @property
    def nonlinear_force_uses_displacement(self) -> bool:
        """False when ``Q_nl`` depends on the velocities only: NLTV friction in formulation A
        (loads quasi-static, ``mu`` from the sliding and rolling velocities) without backlash.
        Backlash (the dead zone of ``delta``, the contact gate of the loads) and nonlinear
        formulation-B loads (``|F_mesh|``, ``max(+-F_mesh, 0)``) use ``q``."""
        m = self.model
        return not m.mesh_is_linear or (not m.friction_is_linear and m.formulation == "B")

    @property
    def piecewise_constant_coefficients(self) -> bool:
        """LTI, or LTV formulation A with a linear mesh of piecewise-constant ``k(t)`` (rectangular,
        or per pair a constant pair stiffness): the homogeneous coefficients are constant between
        the breakpoints (friction an excitation)."""
        m = self.model
        return m.is_linear and (m.coupling == "LTI" or (m.coupling == "LTV" and m.formulation == "A"
                                                         and m.mesh.piecewise_constant))

    def frequency_scale(self, p):
        """``w_n = sqrt(k_mean / m_e)`` [rad/s] of the model at `p`."""
        model, _ = self._at(p)
        return float(np.sqrt(float(model.k_mean_N_per_m) / float(model.mass_equivalent_kg)))

    def neutral_multipliers(self, p, nu: int = 1):
        """The spring boundary's undamped soft mode ``exp(+-i w_b T)`` (:mod:`hbgear.gear.soft_mode`)."""
        from .soft_mode import soft_mode_estimate

        model, omega = self._at(p)
        omega = np.broadcast_to(np.asarray(omega, dtype=float), np.shape(p))
        return soft_mode_estimate(model, omega, nu)

    def arclength_mean_scales(self, p):
        """A non-linear model on the soft output spring: ``u``'s mean counted in units of
        ``k_mean / k_spring`` static deflections (``spring_stiffness_ratio``, the spring's force in
        units of ``N``), else ``None``.

        Where the model is non-linear the mean friction torque follows the response (formulation
        B's loads ``sigma_j |F_mesh|``, NLTV's ``mu(V_s)``, contact lost with backlash or relief),
        and the spring's mean wind-up follows it ``spring_stiffness_ratio`` (5e5) times more than
        the mesh: on ``examples/iso_tip_relief.toml`` (H = 32) it moved by 0.25 scaled units per
        step (``ds_max``) while the DTE's coefficients moved by 5e-4, about 0.1 rpm per step near
        the fold; on the paper's pair with formulation B 4000 points reached 1031 rpm from 1000.
        A linear model's mean friction torque is constant: it keeps the plain metric."""
        model, _ = self._at(p)
        if model.boundary != "spring" or model.is_linear:
            return None
        scales = np.ones(model.ndof)
        scales[model.layout.index("u")] = float(model.spring_stiffness_ratio)
        return scales

    def linearization(self):
        """The system of :func:`linear_equivalent`'s candidate (the model itself if linear; with
        backlash or MODEL.md section 11's compressive loads, the same model with teeth that never
        separate and signed loads), or ``None`` (NLTV)."""
        linear = linear_equivalent(self.model)
        if linear is None:
            return None
        return self if linear is self.model else GearSystem(linear, self.omega_pinion, self.parameter)

    def in_linear_regime(self, hb, z, p) -> bool:
        """Whether the solution `z` (scaled unknowns of `hb`) at `p` keeps the linear equivalent
        (:func:`linear_equivalent` with the solution: contact kept, compressive loads)."""
        model, omega = self._at(p)
        if model.is_linear:
            return True
        return linear_equivalent(model, _SolutionView(self, hb, z, p, float(omega))) is not None

    @property
    def displacement_scale(self):
        return self.model.normal_load_N / self.model.k_mean_N_per_m

    @property
    def force_scale(self):
        return self.model.normal_load_N

    def mass_matrix(self, p, xp=np):
        model, _ = self._at(p)
        return model.mass_matrix(xp)

    def excitation_frequency(self, p):
        model, omega = self._at(p)
        return model.speeds(omega)[2]

    def breakpoints(self, p, xp=np):
        model, _ = self._at(p)
        return model.breakpoint_candidates(xp)

    def derivative_forcing(self, s, p, xp=np):
        """LTI: the stiffness-jump impulses of ``c d_st'`` (:meth:`GearPairModel.lti_step_forcing`)."""
        model, _ = self._at(p)
        return model.lti_step_forcing(s, xp)

    def input_map(self, p):
        """The combinations of the coordinates the mesh and friction see (the rest -- masses,
        bearings, shafts, the output spring -- is linear time-invariant): ``delta``, and for NLTV
        the sliding velocity's ``a_p``, ``a_g`` (unless the ``"torques"`` boundary fixes them at
        nominal) and ``x_p - x_g`` (bearings). ``None`` unless the parameter is the speed (the
        rows follow the masses through the ``"torques"`` projection)."""
        if self.parameter != "speed":
            return None
        model = self.model
        lay = model.layout
        unit = np.eye(lay.ndof)
        rows = [unit[0]]  # delta = q[0]
        if model.coupling == "NLTV":
            if lay.eliminated is None:
                projection = model.projection()
                rows += [np.asarray(projection["a_p"], dtype=float), np.asarray(projection["a_g"], dtype=float)]
            if model.bearings is not None:
                rows.append(unit[lay.index("x_p")] - unit[lay.index("x_g")])
        return np.stack(rows)

    def output_map(self, p):
        """The coordinates the mesh and friction act on (virtual work, MODEL.md section 10): ``delta``
        (the mesh force), the rows of the pinion and gear rotations ``a_p``, ``a_g`` (the friction
        torques) and ``x_p - x_g`` (the friction force on the centres, opposite on the two). With
        NLTV they are the input map's own rows; LTV sees only ``delta`` but acts on all four.
        ``None`` unless the parameter is the speed (as :meth:`input_map`)."""
        if self.parameter != "speed":
            return None
        model = self.model
        lay = model.layout
        projection = model.projection()
        rows = [np.eye(lay.ndof)[0]]
        rows += [np.asarray(projection[name], dtype=float) for name in ("a_p", "a_g")]
        if model.bearings is not None:
            rows.append(np.asarray(projection["x_p"], dtype=float) - np.asarray(projection["x_g"], dtype=float))
        return np.stack(rows)

    @property
    def event_zero_capacity(self) -> tuple[int, int]:
        """Per-pair contact that may open: 32 sign changes and 4 excursions per mesh period (a
        relieved pair near grazing contact: 12 sign changes were measured on
        ``examples/iso_tip_relief.toml`` at 1113 rpm, H = 24, where 8 left two jumps uncorrected and
        the residual jumped by 1e-6 as a third pulse appeared); else the engine's default (8, 2): the
        backlash pair's two flank contacts, at a quarter of the cost per evaluation."""
        if self.model.pairs_may_open:
            return (32, 4)
        return (events.MAX_CROSSINGS, events.MAX_EXCURSIONS)

    def event_functions(self, s, q, qd, p, xp=np):
        """Backlash with friction: the flank contacts ``x -+ b`` (:meth:`GearPairModel.contact_events`)."""
        model, omega = self._at(p)
        return model.contact_events(s, q, omega, xp)

    def force(self, s, q, qd, p, part, extra, xp=np):
        model, omega = self._at(p)
        # the spring's static wind-up enters the constant terms only (not the "nonlinear" part),
        # and costs a quadrature of its own: skip it where it is not used
        needs_windup = model.boundary == "spring" and part != "nonlinear"
        u_static = model.static_windup(omega, xp) if needs_windup else 0.0
        return model.generalized_force(s, q, qd, omega, part, u_static, extra, xp)


class _SolutionView:
    """What :func:`linear_equivalent` reads of a solution (``state_at``, ``harmonics``, ``nu``,
    ``omega_pinion``) from the unknowns `z` of `hb` (the engine's synthesis)."""

    def __init__(self, system, hb, z, p, omega_pinion):
        from ..engine.response import synthesize

        self._synthesize = synthesize
        self._coefficients = hb.decode(system, z)[0]
        self._base_frequency = float(hb.base_frequency(system, p))
        self.harmonics, self.nu, self.omega_pinion = hb.harmonics, hb.nu, omega_pinion

    def state_at(self, base_fraction):
        tau = 2 * np.pi * np.asarray(base_fraction, dtype=float).ravel()
        k = np.arange(1, self.harmonics + 1)
        return self._synthesize(self._coefficients, self._base_frequency, np.cos(np.outer(k, tau)),
                                np.sin(np.outer(k, tau)))


def linear_equivalent(model: GearPairModel, solution=None) -> GearPairModel | None:
    """The linear model whose variational equations are `model`'s along `solution`, or ``None``.

    A linear `model` is its own equivalent; NLTV has none (``mu`` follows the state). Otherwise the
    candidate is `model` with ``contact = "linear"``, ``normal_loads = "signed"`` and its mesh held
    closed (:meth:`~hbgear.gear.mesh.PairContactMesh.closed`): along a solution on which the teeth
    stay in contact (with backlash ``2b``: ``|x| > b``, ``x = delta - eps``; formulation B: the
    drive flank, ``x > b``, with a compressive ``F_mesh > 0``; per-pair contact: every pair of the
    path on its drive flank, ``x > b + e_j``, or for A all on the back flank, and for B every
    ``F_j > 0``) the contact has slope 1 and the loads of MODEL.md section 11 are the affine
    ``N_j,s`` (A; a constant excitation also on the back flank) or ``F_j`` (B), so the
    linearisations coincide and the candidate's exact monodromy applies.

    **Arguments:** `solution`: a :class:`~hbgear.gear.solve.PeriodicSolution` of `model` (anything
    with ``state_at``, ``harmonics``, ``nu``, ``omega_pinion``), checked on a dense grid (8 samples
    per harmonic, at least 1024 per base period) with a margin of 1e-3 of the peak-to-peak of
    ``x`` and of ``F_mesh`` for the values between the samples; ``None``: the candidate itself
    (whether any solution can have one).
    """
    if model.is_linear:
        return model
    if model.coupling == "NLTV":
        return None
    linear = model.replace(contact="linear", normal_loads="signed", mesh=model.mesh.closed())
    if solution is None:
        return linear
    f = np.linspace(0.0, 1.0, max(1024, 8 * solution.harmonics * solution.nu), endpoint=False)
    q, qd = (np.asarray(a) for a in solution.state_at(f))
    s = (f * solution.nu) % 1.0
    omega = float(solution.omega_pinion)
    wm = model.speeds(omega)[2]
    eps, deps = (np.asarray(a) for a in model.static_transmission_error(s, wm, np))
    x = q[0] - eps
    if not model.mesh_is_linear:
        gap = model.mesh.contact_gap(model, s, x, model.formulation)
        if not np.min(gap) > 1e-3 * float(np.ptp(x)) + 1e-15:
            return None
    if model.formulation == "B":
        force = model.mesh.compressive_force(model, s, x, qd[0] - deps, wm)
        if not np.min(force) > 1e-3 * float(np.ptp(force)) + 1e-12 * float(model.normal_load_N):
            return None
    return linear
