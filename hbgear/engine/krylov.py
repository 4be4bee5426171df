r"""Restarted GMRES with a right preconditioner, for the matrix-free Newton and continuation
steps of :mod:`hbgear.engine.structured`, written in JAX: the whole solve is one compiled loop.

Solves ``A x = b`` from ``x = 0`` as ``A M^{-1} y = b``, ``x = M^{-1} y``: with a right
preconditioner the residual GMRES minimises (and the stopping rule reads) is the true one,
``||b - A x||_2``. Arnoldi by classical Gram--Schmidt applied twice (two matrix products per
step instead of ``j`` vector operations; orthogonal to rounding), the least-squares problem by
Givens rotations, whose last entry is the residual norm at every step without forming ``x``.
Shapes are static: a cycle's basis has ``restart + 1`` rows whatever the step (unused rows are
zero), read in chunks of :data:`CHUNK` rows up to the step's, and the triangular solve is padded
by the identity.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

__all__ = ["KrylovInfo", "gmres"]

#: Basis rows per Gram-Schmidt block: a step's orthogonalisation reads only the chunks that hold
#: its ``j + 1`` vectors, not all ``restart + 1`` rows. With the band preconditioner a solve takes
#: a few products (7 a Newton step, 18 a bordered solve to 1e-10 at H = 512): the Newton step at
#: 8194 unknowns 29.5 -> 25.9 ms, at 2050 7.6 -> 6.9 ms, a continuation point at H = 512 26.7 ->
#: 25.3 ms. The loop over chunks costs more where a solve takes many products (66 products with
#: a diagonal operator at 2051 unknowns: 6.7 ms against 5.0 ms reading all 81 rows each step).
CHUNK = 8


class KrylovInfo(NamedTuple):
    """``converged`` (``||b - A x|| <= rtol ||b||``), ``iterations`` (products with ``A``),
    ``relative_residual`` ``||b - A x|| / ||b||`` (of the true residual)."""

    converged: Any
    iterations: Any
    relative_residual: Any


def gmres(apply, b, *, precondition=lambda v: v, rtol, restart: int, max_products: int):
    """``x`` with ``||b - A x||_2 <= rtol ||b||_2`` by GMRES(`restart`), right-preconditioned: a
    JAX function, traced into the caller's compiled program (no return to Python per product).

    **Arguments:** `apply`: ``v -> A v``; `precondition`: ``v -> M^{-1} v`` (linear); `rtol`;
    `restart` (static): Krylov vectors of a cycle; `max_products` (static): products with ``A``
    at most, the true residual recomputed after each cycle counted with them.

    **Returns:** ``(x, KrylovInfo)`` (its fields traced arrays): the best iterate, converged by
    the *true* residual ``b - A x`` of the last cycle (not the Givens estimate alone).
    """
    n = b.shape[0]
    norm_b = jnp.linalg.norm(b)
    target = rtol * norm_b

    def operator(v):
        return apply(precondition(v))

    rows = -(-(restart + 1) // CHUNK) * CHUNK  # the basis's rows, whole chunks

    def chunks(j):
        return (j + CHUNK) // CHUNK  # those holding the rows 0 .. j

    def dots(basis, w, j):
        """``basis[:j+1] @ w`` (zeros past it), chunk by chunk: the cost grows with ``j``."""
        def one(c, h):
            block = jax.lax.dynamic_slice_in_dim(basis, c * CHUNK, CHUNK)
            return jax.lax.dynamic_update_slice_in_dim(h, block @ w, c * CHUNK, 0)

        return jax.lax.fori_loop(0, chunks(j), one, jnp.zeros(rows))

    def combination(basis, h, j):
        """``h[:j+1] @ basis[:j+1]``."""
        def one(c, acc):
            block = jax.lax.dynamic_slice_in_dim(basis, c * CHUNK, CHUNK)
            return acc + jax.lax.dynamic_slice_in_dim(h, c * CHUNK, CHUNK) @ block

        return jax.lax.fori_loop(0, chunks(j), one, jnp.zeros(n))

    def arnoldi_step(carry):
        j, basis, hessenberg, cos, sin, g, _ = carry
        w = operator(basis[j])
        h = dots(basis, w, j)  # the rows past j are zero: so are their entries
        w = w - combination(basis, h, j)
        again = dots(basis, w, j)  # the second Gram-Schmidt pass
        w, h = w - combination(basis, again, j), (h + again)[: restart + 1]
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
        start = (jnp.asarray(0), jnp.zeros((rows, n)).at[0].set(r / beta), jnp.zeros((restart + 1, restart)),
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
    return precondition(u), KrylovInfo(beta <= target, done, relative)
