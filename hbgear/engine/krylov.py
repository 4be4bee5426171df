r"""Restarted GMRES with a right preconditioner, for the matrix-free Newton steps of
:mod:`hbgear.engine.structured`.

Solves ``A x = b`` from ``x = 0`` as ``A M^{-1} y = b``, ``x = M^{-1} y``: with a right
preconditioner the residual GMRES minimises (and the stopping rule reads) is the true one,
``||b - A x||_2``. Arnoldi by classical Gram--Schmidt applied twice (two matrix products per
step instead of ``j`` vector operations; orthogonal to rounding), the least-squares problem by
Givens rotations, whose last entry is the residual norm at every step without forming ``x``.
"""

from __future__ import annotations

from typing import Any, Callable, NamedTuple

import numpy as np
import scipy.linalg

__all__ = ["KrylovInfo", "TracedKrylovInfo", "gmres", "gmres_traced"]


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


class TracedKrylovInfo(NamedTuple):
    """:class:`KrylovInfo` as traced arrays (:func:`gmres_traced`)."""

    converged: Any
    iterations: Any
    relative_residual: Any


def gmres_traced(apply, b, *, precondition=lambda v: v, rtol, restart: int, max_products: int):
    """:func:`gmres` as a JAX function (inside a compiled program: no call back to Python per
    product). ``x`` with ``||b - A x||_2 <= rtol ||b||_2``, right-preconditioned, restarted.

    **Arguments:** `apply`: ``v -> A v``; `precondition`: ``v -> M^{-1} v`` (linear); `rtol`;
    `restart` (static): Krylov vectors of a cycle; `max_products` (static): products with ``A``
    at most, the true residual recomputed after each cycle counted with them.

    **Returns:** ``(x, TracedKrylovInfo)``: the best iterate, converged by the *true* residual
    ``b - A x`` of the last cycle (not the Givens estimate alone).
    """
    import jax
    import jax.numpy as jnp

    n = b.shape[0]
    norm_b = jnp.linalg.norm(b)
    target = rtol * norm_b

    def operator(v):
        return apply(precondition(v))

    def arnoldi_step(carry):
        j, basis, hessenberg, cos, sin, g, _ = carry
        w = operator(basis[j])
        h = basis @ w  # the rows past j are zero: so are their entries
        w = w - h @ basis
        again = basis @ w  # the second Gram-Schmidt pass
        w, h = w - again @ basis, h + again
        norm = jnp.linalg.norm(w)
        column = h.at[j + 1].set(norm)

        def rotate(i, c):  # the earlier rotations on the new column
            a, d = c[i], c[i + 1]
            return c.at[i].set(cos[i] * a + sin[i] * d).at[i + 1].set(-sin[i] * a + cos[i] * d)

        column = jax.lax.fori_loop(0, j, rotate, column)
        a, d = column[j], column[j + 1]
        radius = jnp.hypot(a, d)
        cj = jnp.where(radius == 0.0, 1.0, a / jnp.where(radius == 0.0, 1.0, radius))
        sj = jnp.where(radius == 0.0, 0.0, d / jnp.where(radius == 0.0, 1.0, radius))
        hessenberg = hessenberg.at[:, j].set(column.at[j].set(radius).at[j + 1].set(0.0))
        gj = g[j]
        g = g.at[j].set(cj * gj).at[j + 1].set(-sj * gj)
        basis = basis.at[j + 1].set(jnp.where(norm == 0.0, 0.0, w / jnp.where(norm == 0.0, 1.0, norm)))
        stop = (jnp.abs(g[j + 1]) <= target) | (norm == 0.0)
        return j + 1, basis, hessenberg, cos.at[j].set(cj), sin.at[j].set(sj), g, stop

    def cycle(u, r, beta, steps):
        """One cycle of at most `steps` from the residual `r`: ``(u + V y, products made)``."""
        zeros = jnp.zeros(restart)
        start = (jnp.asarray(0), jnp.zeros((restart + 1, n)).at[0].set(r / beta), jnp.zeros((restart + 1, restart)),
                 zeros, zeros, jnp.zeros(restart + 1).at[0].set(beta), jnp.asarray(False))
        j, basis, hessenberg, _, _, g, _ = jax.lax.while_loop(lambda c: (c[0] < steps) & ~c[-1], arnoldi_step, start)
        # the triangular system of the j columns made, padded to the restart's size by the identity
        active = jnp.arange(restart) < j
        triangle = jnp.where(active[:, None] & active[None, :], hessenberg[:restart], jnp.eye(restart))
        y = jax.scipy.linalg.solve_triangular(triangle, jnp.where(active, g[:restart], 0.0), lower=False)
        return u + y @ basis[:restart], j

    def go_on(state):
        _, _, beta, done, made = state
        return (beta > target) & (done < max_products) & (made > 0)

    def restarted(state):
        u, r, beta, done, _ = state
        u, made = cycle(u, r, beta, jnp.minimum(restart, max_products - done - 1))
        r = b - operator(u)  # the restart's residual, exact
        return u, r, jnp.linalg.norm(r), done + made + 1, made

    u, _, beta, done, _ = jax.lax.while_loop(go_on, restarted, (jnp.zeros_like(b), b, norm_b, jnp.asarray(0),
                                                                  jnp.asarray(1)))
    relative = beta / jnp.where(norm_b == 0.0, 1.0, norm_b)
    return precondition(u), TracedKrylovInfo(beta <= target, done, relative)
