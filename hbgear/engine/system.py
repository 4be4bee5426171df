r"""Periodic mechanical systems in the form the harmonic-balance engine solves.

A system is ``M q'' = Q(s, q, q'; p)`` where ``s`` in [0, 1) is the phase of its excitation
period ``2 pi / w_exc(p)``, ``p`` the scalar parameter being varied (a speed, a torque, ...), and
``Q = Q_lin + Q_nl`` splits into terms affine in ``(q, q')`` with periodic coefficients
(exact convolution) and the rest (alternating frequency-time). Protocol (duck-typed):

- ``ndof`` (int), ``is_linear`` (bool), ``free_mean_dof`` (int or None: a coordinate whose mean
  is pinned to 0 and replaced by a constant force unknown ``extra`` entering ``Q``),
- ``mass_matrix(p, xp)``, ``excitation_frequency(p)`` [rad/s], ``breakpoints(p, xp)``,
- ``force(s, q, qd, p, part, extra, xp)``, ``displacement_scale``, ``force_scale``;
- optional speed-ups (default False): ``coefficients_independent_of_parameter`` (``M`` and
  the periodic stiffness and damping of ``Q_lin`` do not depend on ``p``) and
  ``forcing_affine_in_frequency`` (``Q_lin(s, 0, 0; p) = Fbar(p) + A(s) + w_exc(p) B(s)``);
  and (default True) ``nonlinear_force_uses_displacement`` (False: ``Q_nl`` depends on ``q'``
  only, so its Jacobian has no displacement blocks).

Systems are JAX pytrees, so changing their float parameters never triggers recompilation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from jax.tree_util import register_dataclass


__all__ = ["Duffing"]


@register_dataclass
@dataclass(frozen=True)
class Duffing:
    r"""``x'' + c x' + k x + a x^3 = f cos(w t)``; the parameter is ``w`` [rad/s].

    A generic check of the engine and of continuation (known backbone and jump frequencies).
    """

    damping: float = 0.02
    stiffness: float = 1.0
    cubic: float = 0.1
    forcing: float = 0.05

    ndof = 1
    free_mean_dof = None
    coefficients_independent_of_parameter = True
    forcing_affine_in_frequency = True
    displacement_scale = 1.0
    force_scale = 1.0

    @property
    def is_linear(self) -> bool:
        return False

    def mass_matrix(self, p, xp=np):
        return xp.ones((1, 1))

    def excitation_frequency(self, p):
        return p

    def breakpoints(self, p, xp=np):
        return xp.zeros(1)

    def force(self, s, q, qd, p, part, extra, xp=np):
        linear = self.forcing * xp.cos(2 * np.pi * s) - self.stiffness * q[0] - self.damping * qd[0]
        nonlinear = -self.cubic * q[0] ** 3
        if part == "linear":
            return xp.stack([linear])
        if part == "nonlinear":
            return xp.stack([nonlinear])
        return xp.stack([linear + nonlinear])
