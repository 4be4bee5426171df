"""Damped Newton iteration on a scaled residual, with an honest report.

The residual is scaled (by the static load for the gear pair), so the tolerance is relative to
the static mesh force. A backtracking line search on ``||R||`` keeps the step in the basin of
attraction when friction switches sign; the result always carries the residual reached, and
failure is a status, never a silent answer.
"""

from __future__ import annotations

from typing import Callable, NamedTuple

import numpy as np
import scipy.linalg

__all__ = ["NewtonResult", "newton"]


class NewtonResult(NamedTuple):
    """``z`` the last iterate, ``converged``, ``iterations``, ``residual_norm`` (max-norm, scaled)."""

    z: np.ndarray
    converged: bool
    iterations: int
    residual_norm: float


def newton(
    residual_and_jacobian: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
    residual: Callable[[np.ndarray], np.ndarray],
    z0: np.ndarray,
    *,
    tolerance: float = 1e-9,
    max_iterations: int = 50,
    min_step: float = 1.0 / 1024,
) -> NewtonResult:
    """Solve ``R(z) = 0`` from ``z0``.

    **Arguments:**

    - `residual_and_jacobian`: ``z -> (R, dR/dz)``; `residual`: ``z -> R`` (line search).
    - `tolerance`: on ``max |R|``; `max_iterations`: Newton steps at most;
      `min_step`: smallest line-search fraction before giving up on a step.
    """
    z = np.asarray(z0, dtype=float)
    r, jac = residual_and_jacobian(z)
    r, jac = np.asarray(r), np.asarray(jac)
    norm = float(np.max(np.abs(r)))
    for iteration in range(1, max_iterations + 1):
        if not np.isfinite(norm):
            return NewtonResult(z, False, iteration - 1, norm)
        if norm <= tolerance:
            return NewtonResult(z, True, iteration - 1, norm)
        try:
            step = scipy.linalg.lu_solve(scipy.linalg.lu_factor(jac, check_finite=False), -r, check_finite=False)
        except (np.linalg.LinAlgError, ValueError):
            return NewtonResult(z, False, iteration - 1, norm)
        alpha = 1.0
        while True:
            trial = z + alpha * step
            r_trial = np.asarray(residual(trial))
            trial_norm = float(np.max(np.abs(r_trial)))
            if np.isfinite(trial_norm) and trial_norm < (1 - 1e-4 * alpha) * norm or alpha <= min_step:
                break
            alpha *= 0.5
        z = trial
        r, jac = residual_and_jacobian(z)
        r, jac = np.asarray(r), np.asarray(jac)
        norm = float(np.max(np.abs(r)))
    return NewtonResult(z, norm <= tolerance, max_iterations, norm)
