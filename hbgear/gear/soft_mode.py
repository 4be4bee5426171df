r"""The soft output mode of the ``"spring"`` boundary in the stability verdict.

The ``"spring"`` boundary ties the gear to ground through the soft spring ``k_u = k_mean / ratio``
(MODEL.md section 4), a device that stands for the free output rotation (the ``"reaction"``
boundary's rigid-body mode). Its mode, at ``w_b = sqrt(k_u / (m_p + m_g))`` far below the mesh
mode, has no damping of its own with ``boundary.damping_ratio = 0``, and the mesh barely couples
to it: for LTV its exact multipliers are ``exp(+-i w_b T)`` to ~3e-9 and their modulus is
``1 +- 1e-10`` (exact monodromy: ``1 - 3.6e-14`` at 3000 rpm, ``1 + 9.1e-11`` at 13,400 rpm, where
``k(t)`` couples it weakly to the mesh mode). A verdict taken on that modulus would rest on the
tolerance of :func:`hbgear.engine.floquet.is_stable` and on the method's accuracy (Hill's
method errs on this modulus by up to ~6e-7 for NLTV at N = 256 AFT samples: Coulomb law
regularised at 5 mm/s, 13,400 rpm, against the variational monodromy). NLTV friction damps the
mode a little (modulus 1 - 2.9e-6 at 3000 rpm with that law).

**Rule.** The conjugate pair of multipliers within :data:`NEUTRAL_TOL` of ``exp(+-i w_b T)`` (``T``
the base period, ``nu`` mesh periods) is the neutral soft mode: it is reported, and excluded from
the verdict like the trivial pair of the ``"reaction"`` boundary (:data:`~hbgear.engine.floquet.TRIVIAL_TOL`,
the same band), so both boundaries judge the same mesh. A soft-mode multiplier farther from
``exp(+-i w_b T)`` -- damped by ``boundary.damping_ratio`` or by NLTV friction, or driven out of
the unit circle by it -- is an ordinary multiplier and counts.
"""

from __future__ import annotations

import numpy as np

from ..engine.floquet import TRIVIAL_TOL, is_stable, neutral_mask, split_neutral

__all__ = ["NEUTRAL_TOL", "soft_mode_estimate", "split_soft_mode", "stable_verdict", "stable_verdicts"]

#: Distance from ``exp(+-i w_b T)`` within which a multiplier is the neutral soft mode (the
#: trivial band of the reaction boundary; > 10x Hill's largest measured error on this mode).
NEUTRAL_TOL = TRIVIAL_TOL


def soft_mode_estimate(model, omega_pinion, nu: int = 1) -> np.ndarray:
    """``exp(+-i w_b T)``, ``w_b = sqrt(k_u/(m_p + m_g))``, ``T = 2 pi nu / w_mesh``: the uncoupled,
    undamped soft mode's multipliers, shape ``np.shape(omega_pinion) + (2,)`` (``"spring"``
    boundary; last axis empty otherwise)."""
    omega = np.asarray(omega_pinion, dtype=float)
    if model.boundary != "spring":
        return np.zeros(omega.shape + (0,), dtype=complex)
    w_b = np.sqrt(float(model.spring_stiffness_N_per_m) / float(model.rigid_mass_kg))
    period = 2.0 * np.pi * nu / (float(model.teeth_pinion) * omega)
    return np.exp(np.multiply.outer(w_b * period, np.array([1j, -1j])))


def split_soft_mode(model, omega_pinion: float, multipliers, nu: int = 1):
    """``(others, soft)``: the multipliers less the neutral soft-mode pair, and that pair (empty
    when there is none, or when the mode is damped or driven away from ``exp(+-i w_b T)``)."""
    return split_neutral(multipliers, soft_mode_estimate(model, omega_pinion, nu), NEUTRAL_TOL)


def stable_verdict(model, omega_pinion: float, multipliers, nu: int = 1) -> bool:
    """The gear pair's stability: :func:`~hbgear.engine.floquet.is_stable` of the multipliers
    (trivial ones already dropped) less the neutral soft mode of the spring boundary."""
    return is_stable(split_soft_mode(model, omega_pinion, multipliers, nu)[0])


def stable_verdicts(model, omegas, multipliers, nu: int = 1, tol: float = 1e-9) -> np.ndarray:
    """:func:`stable_verdict` at many points at once: `multipliers` ``(P, k)`` at `omegas` ``(P,)``;
    booleans ``(P,)`` (a non-finite multiplier makes its point unstable, as in ``is_stable``)."""
    m = np.asarray(multipliers)
    mask = neutral_mask(m, soft_mode_estimate(model, omegas, nu), NEUTRAL_TOL)
    modulus = np.where(mask, 0.0, np.abs(m))
    return np.all(np.isfinite(m), axis=-1) & (np.max(modulus, axis=-1, initial=0.0) <= 1.0 + tol)
