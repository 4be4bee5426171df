"""Damped Newton iteration on a scaled residual, with an honest report.

The residual is scaled (by the static load for the gear pair), so the tolerance is relative to
the static mesh force. A backtracking line search on ``||R||`` keeps the step in the basin of
attraction when friction switches sign; the result always carries the residual reached, and
failure is a status, never a silent answer.

The Jacobian is a dense matrix (LU, an exact step) or a matrix-free linearisation with
``solve(b, rtol)`` (e.g. :class:`hbgear.engine.structured.StructuredJacobian`): an inexact
Newton step, ``||J s + R||_2 <= eta_k ||R||_2``, with the Eisenstat--Walker forcing term
(choice 2, safeguarded as in Kelley, *Solving Nonlinear Equations with Newton's Method*, 2003)

    eta_k = min(ETA_MAX, max(GAMMA (|R_k| / |R_{k-1}|)^2, GAMMA eta_{k-1}^2 [if > 0.1], 0.5 tol / |R_k|))

loose far from the root, tight near it (superlinear convergence), never tighter than the
tolerance needs.
"""

from __future__ import annotations

from typing import Callable, NamedTuple

import numpy as np
import scipy.linalg

__all__ = ["NewtonResult", "newton", "ETA_MAX", "GAMMA"]

#: Eisenstat--Walker forcing terms of the inexact steps: the loosest relative linear residual
#: (also the first step's), and the factor of the squared residual ratio.
ETA_MAX = 1e-2
GAMMA = 0.9


class NewtonResult(NamedTuple):
    """``z`` the last iterate, ``converged``, ``iterations``, ``residual_norm`` (max-norm, scaled),
    ``linear_iterations`` (products of the Krylov solves; 0 for dense steps)."""

    z: np.ndarray
    converged: bool
    iterations: int
    residual_norm: float
    linear_iterations: int = 0


def newton(
    residual_and_jacobian: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
    residual: Callable[[np.ndarray], np.ndarray],
    z0: np.ndarray,
    *,
    tolerance: float = 1e-9,
    max_iterations: int = 50,
    min_step: float = 1.0 / 1024,
    linear_rtol: float | None = None,
) -> NewtonResult:
    """Solve ``R(z) = 0`` from ``z0``.

    **Arguments:**

    - `residual_and_jacobian`: ``z -> (R, J)``, ``J`` the dense ``dR/dz`` or a linearisation
      with ``solve(b, rtol) -> (x, info)`` (``info.relative_residual``, ``info.iterations``);
      `residual`: ``z -> R`` (line search).
    - `tolerance`: on ``max |R|``; `max_iterations`: Newton steps at most;
      `min_step`: smallest line-search fraction before giving up on a step;
      `linear_rtol`: the relative residual of every inexact step (default: the forcing terms
      of the module docstring; a linear problem passes ``~tolerance`` to be done in one step).

    A matrix-free step that does not reduce the linear residual at all ends the iteration
    (not converged, the residual reached reported).
    """
    z = np.asarray(z0, dtype=float)
    r, jac = _evaluate(residual_and_jacobian, z)
    norm = float(np.max(np.abs(r)))
    eta, previous, products = ETA_MAX, None, 0
    for iteration in range(1, max_iterations + 1):
        if not np.isfinite(norm):
            return NewtonResult(z, False, iteration - 1, norm, products)
        if norm <= tolerance:
            return NewtonResult(z, True, iteration - 1, norm, products)
        if isinstance(jac, np.ndarray):
            try:
                step = scipy.linalg.lu_solve(scipy.linalg.lu_factor(jac, check_finite=False), -r, check_finite=False)
            except (np.linalg.LinAlgError, ValueError):
                return NewtonResult(z, False, iteration - 1, norm, products)
        else:
            norm2 = float(np.linalg.norm(r))
            eta = _forcing(norm2, previous, eta, tolerance) if linear_rtol is None else linear_rtol
            previous = norm2
            step, info = jac.solve(-r, eta)
            products += info.iterations
            if not info.relative_residual < 1.0:
                return NewtonResult(z, False, iteration - 1, norm, products)
        alpha = 1.0
        while True:
            trial = z + alpha * step
            r_trial = np.asarray(residual(trial))
            trial_norm = float(np.max(np.abs(r_trial)))
            if np.isfinite(trial_norm) and trial_norm < (1 - 1e-4 * alpha) * norm or alpha <= min_step:
                break
            alpha *= 0.5
        z = trial
        r, jac = _evaluate(residual_and_jacobian, z)
        norm = float(np.max(np.abs(r)))
    return NewtonResult(z, norm <= tolerance, max_iterations, norm, products)


def _evaluate(residual_and_jacobian, z):
    """``(R, J)`` as numpy (``J`` kept as it is when it is not an array)."""
    r, jac = residual_and_jacobian(z)
    return np.asarray(r), jac if hasattr(jac, "solve") else np.asarray(jac)


def _forcing(norm, previous, eta, tolerance) -> float:
    """The Eisenstat--Walker forcing term (module docstring) from the residual 2-norms."""
    if previous is None:
        return ETA_MAX
    value = GAMMA * (norm / previous) ** 2
    if GAMMA * eta**2 > 0.1:
        value = max(value, GAMMA * eta**2)
    return min(ETA_MAX, max(value, 0.5 * tolerance / norm))
