"""The gear pair as a periodic system of the harmonic-balance engine (:mod:`hbgear.engine.system`)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from jax.tree_util import register_dataclass

from ..engine.fourier import basis_size
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

    def linearization(self):
        """The linear model itself, or for a backlash model (otherwise linear) the same model with
        teeth that never separate: ``g(x)`` has slope 1 outside the dead zone, so along a solution
        that keeps contact the linearisation is exactly that model's."""
        if self.model.is_linear:
            return self
        if self.model.contact == "backlash":
            linear = self.model.replace(contact="linear")
            if linear.is_linear:
                return GearSystem(linear, self.omega_pinion, self.parameter)
        return None

    def in_linear_regime(self, hb, z, p) -> bool:
        """True unless the model has backlash and the solution enters the dead zone: ``|delta -
        eps| > b`` on a dense grid (8 samples per harmonic, at least 1024 per base period) with a
        margin of 1e-3 of its peak-to-peak for the values between the samples."""
        model, omega = self._at(p)
        if model.contact != "backlash":
            return True
        x = np.asarray(z, dtype=float).reshape(model.ndof, basis_size(hb.harmonics))[0] * float(self.displacement_scale)
        f = np.linspace(0.0, 1.0, max(1024, 8 * hb.harmonics * hb.nu), endpoint=False)
        k = np.arange(1, hb.harmonics + 1)
        angle = 2 * np.pi * np.outer(f, k)
        delta = x[0] + np.cos(angle) @ x[1::2] + np.sin(angle) @ x[2::2]
        eps, _ = model.static_transmission_error((f * hb.nu) % 1.0, model.speeds(float(omega))[2], np)
        gap = delta - np.asarray(eps)
        return bool(np.min(np.abs(gap)) - 0.5 * model.backlash_m > 1e-3 * float(np.ptp(gap)) + 1e-15)

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

    def force(self, s, q, qd, p, part, extra, xp=np):
        model, omega = self._at(p)
        # the spring's static wind-up enters the constant terms only (not the "nonlinear" part),
        # and costs a quadrature of its own: skip it where it is not used
        needs_windup = model.boundary == "spring" and part != "nonlinear"
        u_static = model.static_windup(omega, xp) if needs_windup else 0.0
        return model.generalized_force(s, q, qd, omega, part, u_static, extra, xp)
