"""The gear pair as a periodic system of the harmonic-balance engine (:mod:`hbgear.engine.system`)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from jax.tree_util import register_dataclass

from ..engine.system import PeriodicSystem
from .model import GearPairModel

__all__ = ["GearSystem"]


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

        In a speed sweep they come from ``k(t)``, ``c(t)`` and, for formulation B with a
        linear-friction coupling, the nominal friction factors: those depend on the speed only
        through a law with a velocity scale (arctan, Kelley--Lemanski).
        """
        if self.parameter != "speed":
            return False
        m = self.model
        friction_in_coefficients = m.friction_is_linear and m.formulation == "B"
        return not friction_in_coefficients or m.friction.name in ("none", "coulomb")

    @property
    def forcing_affine_in_frequency(self) -> bool:
        """True when the forcing (the linear part at ``q = q' = 0``) is ``Fbar(w) + A(s) + w B(s)``.

        In a speed sweep the mesh term ``-k eps - c eps'`` is affine in ``w`` (``eps' ~ w_m``),
        the input/output torques and the spring's wind-up ``u_s(w)`` are constant in ``s``; only
        a linear friction term with a velocity scale (arctan, Kelley--Lemanski in LTI/LTV)
        depends on the speed otherwise. Checked numerically by the harmonic balance.
        """
        if self.parameter != "speed":
            return False
        m = self.model
        return not m.friction_is_linear or m.friction.name in ("none", "coulomb")

    @property
    def nonlinear_force_uses_displacement(self) -> bool:
        """False when ``Q_nl`` depends on the velocities only: NLTV friction in formulation A
        (loads quasi-static, ``mu`` from the sliding and rolling velocities) without backlash.
        Backlash (the dead zone of ``delta``) and formulation-B loads (``F_mesh``) use ``q``."""
        m = self.model
        return not m.mesh_is_linear or (not m.friction_is_linear and m.formulation == "B")

    @property
    def piecewise_constant_coefficients(self) -> bool:
        """LTI, or LTV formulation A, without backlash: the homogeneous coefficients are constant
        between the breakpoints (``k(t)`` a rectangular pulse, friction an excitation)."""
        m = self.model
        return m.is_linear and (m.coupling == "LTI" or (m.coupling == "LTV" and m.formulation == "A"))

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

    def force(self, s, q, qd, p, part, extra, xp=np):
        model, omega = self._at(p)
        # the spring's static wind-up enters the constant terms only (not the "nonlinear" part),
        # and costs a quadrature of its own: skip it where it is not used
        needs_windup = model.boundary == "spring" and part != "nonlinear"
        u_static = model.static_windup(omega, xp) if needs_windup else 0.0
        return model.generalized_force(s, q, qd, omega, part, u_static, extra, xp)
