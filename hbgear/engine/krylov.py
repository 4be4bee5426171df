r"""Restarted GMRES with a right preconditioner, for the matrix-free Newton steps of
:mod:`hbgear.engine.structured`.

Solves ``A x = b`` from ``x = 0`` as ``A M^{-1} y = b``, ``x = M^{-1} y``: with a right
preconditioner the residual GMRES minimises (and the stopping rule reads) is the true one,
``||b - A x||_2``. Arnoldi by classical Gram--Schmidt applied twice (two matrix products per
step instead of ``j`` vector operations; orthogonal to rounding), the least-squares problem by
Givens rotations, whose last entry is the residual norm at every step without forming ``x``.
"""

from __future__ import annotations

from typing import Callable, NamedTuple

import numpy as np
import scipy.linalg

__all__ = ["KrylovInfo", "gmres"]


class KrylovInfo(NamedTuple):
    """``converged`` (``||b - A x|| <= rtol ||b||``), ``iterations`` (products with ``A``),
    ``relative_residual`` ``||b - A x|| / ||b||`` (the Givens estimate; exact to rounding)."""

    converged: bool
    iterations: int
    relative_residual: float


def gmres(
    operator: Callable[[np.ndarray], np.ndarray],
    b: np.ndarray,
    *,
    precondition: Callable[[np.ndarray], np.ndarray] = lambda v: v,
    rtol: float = 1e-8,
    restart: int = 60,
    max_iterations: int = 600,
) -> tuple[np.ndarray, KrylovInfo]:
    """``x`` with ``||b - A x||_2 <= rtol ||b||_2`` by GMRES(`restart`), right-preconditioned.

    **Arguments:** `operator`: ``v -> A M^{-1} v`` (``A`` itself without a preconditioner);
    `b`: the right-hand side; `precondition`: ``v -> M^{-1} v`` (applied once, to the solution
    ``u`` of ``A M^{-1} u = b``); `rtol`: relative residual wanted; `restart`: Krylov vectors
    kept before a restart; `max_iterations`: products with ``A`` at most.

    **Returns:** ``(x, KrylovInfo)``; ``x`` is the best iterate reached even when not converged.
    """
    b = np.asarray(b, dtype=float)
    norm_b = float(np.linalg.norm(b))
    u = np.zeros_like(b)
    if norm_b == 0.0:
        return u, KrylovInfo(True, 0, 0.0)
    r, beta, done = b, norm_b, 0
    while True:
        correction, steps, beta = _cycle(operator, r, beta, rtol * norm_b, min(restart, max_iterations - done))
        u = u + correction
        done += steps
        if beta <= rtol * norm_b or done >= max_iterations or steps == 0:
            return precondition(u), KrylovInfo(bool(beta <= rtol * norm_b), done, beta / norm_b)
        r = b - operator(u)  # the restart's residual, exact
        beta = float(np.linalg.norm(r))


def _cycle(operator, r, beta, target, steps):
    """One GMRES cycle of at most `steps` from the residual `r` (norm `beta`): the correction
    ``V y`` (preconditioned space), the products made, and the residual norm reached."""
    basis = np.empty((steps + 1, r.size))
    basis[0] = r / beta
    hessenberg = np.zeros((steps + 1, steps))
    cos, sin = np.zeros(steps), np.zeros(steps)
    g = np.zeros(steps + 1)
    g[0] = beta
    j = 0
    while j < steps:
        w = operator(basis[j])
        h = basis[: j + 1] @ w
        w = w - h @ basis[: j + 1]
        again = basis[: j + 1] @ w  # the second Gram-Schmidt pass
        w, h = w - again @ basis[: j + 1], h + again
        hessenberg[: j + 1, j] = h
        hessenberg[j + 1, j] = norm = float(np.linalg.norm(w))
        for i in range(j):  # earlier rotations on the new column
            a, c = hessenberg[i, j], hessenberg[i + 1, j]
            hessenberg[i, j], hessenberg[i + 1, j] = cos[i] * a + sin[i] * c, -sin[i] * a + cos[i] * c
        a, c = hessenberg[j, j], hessenberg[j + 1, j]
        radius = float(np.hypot(a, c))
        cos[j], sin[j] = (1.0, 0.0) if radius == 0.0 else (a / radius, c / radius)
        hessenberg[j, j], hessenberg[j + 1, j] = radius, 0.0
        g[j], g[j + 1] = cos[j] * g[j], -sin[j] * g[j]
        j += 1
        if abs(g[j]) <= target or norm == 0.0:
            break
        basis[j] = w / norm
    if j == 0:
        return np.zeros_like(r), 0, beta
    y = scipy.linalg.solve_triangular(hessenberg[:j, :j], g[:j], check_finite=False)
    return y @ basis[:j], j, abs(float(g[j]))
