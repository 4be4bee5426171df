"""The Python corrector of a continuation step: :func:`hbgear.engine.newton.newton` on the
bordered system, then the tangent at the converged point.

The corrector solves, from a predictor ``y_pred`` in the scaled unknowns ``y = (z, p / p_ref)``,

$$B(y) = \\begin{pmatrix} R(z, p_{ref} y_p) \\\\ row \\cdot y - target \\end{pmatrix} = 0,
\\qquad \\frac{\\partial B}{\\partial y} = \\begin{pmatrix} R_z & p_{ref} R_p \\\\ row^T \\end{pmatrix}$$

by the engine's Newton: the full step evaluated with its Jacobian, a residual-only halving down
to ``1/8`` (:data:`LINE_SEARCH_MIN_STEP`) on ``max |R|`` when it does not decrease, converged
when ``max |R| <= tolerance`` and the constraint holds to ``1e-12 (1 + |target|)``. Its outcome
is a :class:`_Point` (with the unit tangent at the point) or a :class:`_Failure`;
:mod:`.compiled` is the same algorithm compiled, with the same outcomes.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..condensed import as_matrix
from ..newton import NewtonStatus, newton
from .steps import _tangent

#: Cost of a chord iteration (one residual, two triangular solves) in Newton iterations (one
#: (R, R_z, R_p) evaluation and one LU): the residual is about half an evaluation's cost.
CHORD_ITERATION_WORK = 0.5

#: The corrector's line search halves the Newton step down to this fraction, taken then as it is.
LINE_SEARCH_MIN_STEP = 1.0 / 8


class _Point(NamedTuple):
    y: np.ndarray  # (z, p/p_ref)
    r_norm: float
    tangent: np.ndarray  # unit tangent at y, oriented along the `previous` given to the corrector
    iterations: int  # Newton + chord iterations (stored with the point)
    work: float  # Newton-equivalent iterations, for the step-size control: Newton + chord / 2


class _Failure(NamedTuple):
    reason: str
    r_norm: float
    iterations: int


_REASONS = {NewtonStatus.NONFINITE: "non-finite residual", NewtonStatus.SINGULAR_JACOBIAN: "singular bordered Jacobian"}


def _failure(status, r_norm, iterations, max_iter) -> _Failure:
    """A corrector run that did not converge, as both correctors report it (`status` a
    :class:`~hbgear.engine.newton.NewtonStatus` value)."""
    if status == NewtonStatus.MAX_ITERATIONS:
        return _Failure(f"not converged in {max_iter} corrector iterations", r_norm, int(max_iter))
    return _Failure(_REASONS[NewtonStatus(status)], r_norm, iterations)


def _python_corrector(residual_and_jacobians, residual, scale, size):
    """``correct(y_pred, row, target, previous, max_iter, tolerance) -> _Point | _Failure``:
    Newton on ``R(y) = 0``, ``row . y = target`` (module doc), then the tangent at the converged
    point from the Jacobian already evaluated there."""

    def evaluate(y):
        """``(R, A)``: ``A`` the bordered matrix ``[[R_z, R_p p_ref], [.]]``, last row unset."""
        r, jz, jp = residual_and_jacobians(y[:-1], float(y[-1] * scale))
        a = np.empty((size + 1, size + 1), order="F")
        a[:size, :size] = np.asarray(as_matrix(jz), dtype=float)  # a structured R_z as a matrix
        a[:size, size] = scale * np.asarray(jp, dtype=float).reshape(-1)
        return np.asarray(r, dtype=float), a

    def bordered(r, y, row, target):
        """``(R, row . y - target)``."""
        out = np.empty(size + 1)
        out[:size] = r
        out[size] = row @ y - target
        return out

    def correct(y_pred, row, target, previous, max_iter, tolerance):
        def bordered_and_jacobian(y):
            r, a = evaluate(y)
            a[size] = row
            return bordered(r, y, row, target), a

        def bordered_residual(y):
            return bordered(np.asarray(residual(y[:-1], float(y[-1] * scale))), y, row, target)

        result = newton(bordered_and_jacobian, bordered_residual, y_pred, tolerance=tolerance, max_iterations=max_iter,
                        min_step=LINE_SEARCH_MIN_STEP, jacobian_at_full_step=True, constraints=1,
                        constraint_tolerance=1e-12 * (1 + abs(target)))
        if not result.converged:
            return _failure(result.status, result.residual_norm, result.iterations, max_iter)
        tangent = _tangent(result.jacobian, previous)
        return _Point(result.z, result.residual_norm, tangent, result.iterations, result.iterations)

    return correct
