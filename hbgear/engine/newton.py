"""Damped Newton iteration on a scaled residual, with an honest report.

The residual is scaled (by the static load for the gear pair), so the tolerance is relative to
the static mesh force. A backtracking line search on ``max |R|`` keeps the step in the basin of
attraction when friction switches sign; the result always carries the residual reached and a
:class:`NewtonStatus`, never a silent answer.

The Jacobian is a dense matrix (LU, an exact step) or a matrix-free linearisation with
``solve(b, rtol)`` (the structured path of many harmonics,
:class:`hbgear.engine.structured.StructuredJacobian`): an inexact step,
``||J s + R||_2 <= eta_k ||R||_2``, with the Eisenstat--Walker forcing term (choice 2, safeguarded
as in Kelley, *Solving Nonlinear Equations with Newton's Method*, 2003)

    eta_k = min(ETA_MAX, max(GAMMA (|R_k| / |R_{k-1}|)^2, GAMMA eta_{k-1}^2 [if > 0.1], 0.5 tol / |R_k|))

loose far from the root, tight near it (superlinear convergence), never tighter than the
tolerance needs.

This is the one Newton of the engine: :func:`hbgear.engine.continuation` runs it on the bordered
system of a continuation step (``R(y) = 0``, ``row . y = target``; ``constraints=1``), and its
compiled corrector is the same algorithm as a JAX loop (the same statuses, by value).
"""

from __future__ import annotations

import enum
import math
from typing import Callable, NamedTuple

import numpy as np
import scipy.linalg

__all__ = ["NewtonResult", "NewtonStatus", "newton", "ETA_MAX", "GAMMA"]

#: Eisenstat--Walker forcing terms of the inexact steps: the loosest relative linear residual
#: (also the first step's), and the factor of the squared residual ratio.
ETA_MAX = 1e-2
GAMMA = 0.9

#: The line search takes ``z + alpha dz`` once ``max |R|`` falls below ``(1 - SUFFICIENT_DECREASE alpha)``
#: times its value at ``z`` (Armijo's condition on the max-norm).
SUFFICIENT_DECREASE = 1e-4


class NewtonStatus(enum.IntEnum):
    """Outcome of a Newton run (the compiled continuation corrector reports the same values)."""

    CONVERGED = 0  # max|R| <= tolerance (and the constraints hold)
    NONFINITE = 1  # the residual at the iterate is NaN or inf
    SINGULAR_JACOBIAN = 2  # the Newton step could not be solved for, or is not finite
    MAX_ITERATIONS = 3  # max_iterations steps taken, not converged
    LINEAR_SOLVE_STALLED = 4  # a matrix-free step's Krylov solve did not reduce the linear residual


_ADVICE = {
    NewtonStatus.CONVERGED: "",
    NewtonStatus.NONFINITE: "the residual is not finite at the iterate (the model left its domain); "
    "try a start closer to the solution or a smaller continuation step",
    NewtonStatus.SINGULAR_JACOBIAN: "the Jacobian is singular there (a fold or bifurcation of a fixed-parameter "
    "problem); follow the branch by continuation, or solve at a slightly different parameter",
    NewtonStatus.MAX_ITERATIONS: "try more iterations, a start closer to the solution (a smaller continuation "
    "step) or a smoother model",
    NewtonStatus.LINEAR_SOLVE_STALLED: "GMRES made no progress on the Newton step (its preconditioner, the mean "
    "Jacobian, misses this linearisation); try the dense path (HarmonicBalance(operator='dense')) or a start "
    "closer to the solution",
}


class NewtonResult(NamedTuple):
    """``z`` the last iterate; `status`; ``iterations`` Newton steps taken; ``residual_norm``
    ``max |R|`` at `z` (scaled; constraints left out); ``jacobian`` ``dR/dz`` evaluated at `z`
    (or the matrix-free linearisation); ``linear_iterations`` products of the Krylov solves (0 for
    dense steps)."""

    z: np.ndarray
    status: NewtonStatus
    iterations: int
    residual_norm: float
    jacobian: np.ndarray | None = None
    linear_iterations: int = 0

    @property
    def converged(self) -> bool:
        return self.status == NewtonStatus.CONVERGED

    @property
    def message(self) -> str:
        """What happened, with the residual reached, and what to try."""
        if self.converged:
            return f"converged to max|R| = {self.residual_norm:.3e} in {self.iterations} Newton iterations"
        return (f"Newton stopped ({self.status.name.lower().replace('_', ' ')}) after {self.iterations} iterations "
                f"at max|R| = {self.residual_norm:.3e}: {_ADVICE[self.status]}")


def _line_search(residual_and_jacobian, residual, z, step, norm, merit, min_step, jacobian_at_full_step):
    """The damped step ``z + alpha step``: the first of ``alpha = 1, 1/2, 1/4, ...`` with
    ``merit(R(z + alpha step)) < (1 - 1e-4 alpha) norm`` (:data:`SUFFICIENT_DECREASE`), or the
    first ``alpha <= min_step``, taken then as it is.

    The trials are residual-only evaluations, except the full step with
    `jacobian_at_full_step` (evaluated with its Jacobian, kept when the step is taken: one
    evaluation per iteration where full steps are the rule, as on a continuation curve).

    **Returns:** ``(z_new, R, dR/dz, merit(R))`` at the step taken.
    """
    alpha = 1.0
    jac = None
    while True:
        trial = z + alpha * step
        if alpha == 1.0 and jacobian_at_full_step:
            r, jac = residual_and_jacobian(trial)
            value = merit(r)
        else:
            value = merit(residual(trial))
        if math.isfinite(value) and value < (1 - SUFFICIENT_DECREASE * alpha) * norm or alpha <= min_step:
            break
        alpha *= 0.5
        jac = None
    if jac is None:
        r, jac = residual_and_jacobian(trial)
        value = merit(r)
    return trial, r, jac, value


def newton(
    residual_and_jacobian: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
    residual: Callable[[np.ndarray], np.ndarray],
    z0: np.ndarray,
    *,
    tolerance: float = 1e-9,
    max_iterations: int = 50,
    min_step: float = 1.0 / 1024,
    jacobian_at_full_step: bool = False,
    constraints: int = 0,
    constraint_tolerance: float = 0.0,
    linear_rtol: float | None = None,
) -> NewtonResult:
    """Solve ``R(z) = 0`` from ``z0``: ``z <- z + alpha dz``, ``dR/dz dz = -R``, ``alpha`` from
    the backtracking line search on ``max |R|`` (:func:`_line_search`).

    **Arguments:**

    - `residual_and_jacobian`: ``z -> (R, J)``, ``J`` the dense ``dR/dz`` or a linearisation with
      ``solve(b, rtol) -> (x, info)`` (``info.relative_residual``, ``info.iterations``; an
      inexact step, module docstring); `residual`: ``z -> R`` (line search).
    - `tolerance`: on ``max |R|``; `max_iterations`: Newton steps at most;
      `min_step`: smallest line-search fraction (the step is taken there, whatever it gives).
    - `jacobian_at_full_step`: evaluate the full step with its Jacobian (see :func:`_line_search`).
    - `constraints`: the last `constraints` equations are linear (a bordered system, e.g.
      ``row . z - target``): they are left out of ``max |R|`` (the tolerance's and the line
      search's measure; a step fraction ``alpha`` scales their error by ``1 - alpha``) and must
      hold to `constraint_tolerance` (absolute) for convergence.
    - `linear_rtol`: the relative residual of every inexact step (default: the forcing terms;
      a linear problem passes ``~tolerance`` to be done in one step).

    **Returns:** a :class:`NewtonResult`; failure is its `status`, never an exception.
    """
    end = None if constraints == 0 else -constraints

    def merit(r):
        return float(np.abs(np.asarray(r)[:end]).max())

    z = np.array(z0, dtype=float)
    r, jac = residual_and_jacobian(z)
    norm = merit(r)
    eta, previous, products = ETA_MAX, None, 0
    for iteration in range(max_iterations + 1):
        if not math.isfinite(norm):
            return NewtonResult(z, NewtonStatus.NONFINITE, iteration, norm, jac, products)
        r = np.asarray(r)
        if norm <= tolerance and (end is None or float(np.abs(r[end:]).max()) <= constraint_tolerance):
            return NewtonResult(z, NewtonStatus.CONVERGED, iteration, norm, jac, products)
        if iteration == max_iterations:
            break
        if hasattr(jac, "solve"):  # matrix-free: an inexact step
            norm2 = float(np.linalg.norm(r))
            eta = _forcing(norm2, previous, eta, tolerance) if linear_rtol is None else linear_rtol
            previous = norm2
            step, info = jac.solve(-r, eta)
            products += info.iterations
            if not info.relative_residual < 1.0:
                return NewtonResult(z, NewtonStatus.LINEAR_SOLVE_STALLED, iteration, norm, jac, products)
        else:
            try:
                step = scipy.linalg.lu_solve(scipy.linalg.lu_factor(np.asarray(jac), check_finite=False), -r,
                                             check_finite=False)
            except (np.linalg.LinAlgError, ValueError):
                return NewtonResult(z, NewtonStatus.SINGULAR_JACOBIAN, iteration, norm, jac, products)
        if not np.all(np.isfinite(step)):
            return NewtonResult(z, NewtonStatus.SINGULAR_JACOBIAN, iteration, norm, jac, products)
        z, r, jac, norm = _line_search(residual_and_jacobian, residual, z, step, norm, merit, min_step,
                                       jacobian_at_full_step)
    return NewtonResult(z, NewtonStatus.MAX_ITERATIONS, max_iterations, norm, jac, products)


def _forcing(norm, previous, eta, tolerance) -> float:
    """The Eisenstat--Walker forcing term (module docstring) from the residual 2-norms."""
    if previous is None:
        return ETA_MAX
    value = GAMMA * (norm / previous) ** 2
    if GAMMA * eta**2 > 0.1:
        value = max(value, GAMMA * eta**2)
    return min(ETA_MAX, max(value, 0.5 * tolerance / norm))
