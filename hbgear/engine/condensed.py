r"""The condensed path of harmonic balance: Newton and continuation steps of a system whose
coordinates are mostly linear time-invariant, solved on its few *ports* (Woodbury).

A system may declare an ``input_map(p)``, a matrix ``C`` (``m x ndof``), with the promise that the
part of its force that is not linear time-invariant depends on the state only through ``C q``
and ``C q'``:

.. math::  Q(s, q, q') = -K_0 q - C_0 q' + \tilde Q(s, C q, C q')

for some constant ``K_0``, ``C_0`` (bearings, shafts, masses: the LTI structure) and any
``\tilde Q`` (the time-varying, nonlinear mesh). The engine checks the promise at a probe state
(:func:`check_input_map`); it never needs ``K_0``, ``C_0`` themselves.

Then the harmonic-balance Jacobian is, with ``B = 2H+1`` and ``x`` coordinate-major,

.. math::  J = A + U (C \otimes I_B),

where ``A`` is the mean Jacobian, block-diagonal per harmonic (``Kb - (k w)^2 M`` on the
diagonal, ``+-k w Cb`` off it, bars the time averages of the periodic stiffness and damping of
``Q_lin`` minus those of the sampled derivatives of ``Q_nl``), and ``U = (J - A)(C^+ \otimes I_B)``
(``n B x m B``, ``C^+`` a right inverse): the difference ``J - A`` vanishes on the directions
``C q = 0`` because the time-varying and nonlinear terms do not see them and the means in ``A``
see them no more. ``U`` costs ``m``
pointwise directional derivatives of ``Q_nl`` and the convolution matrices of ``K(s) C^+``,
``C(s) C^+`` -- no ``n B`` tangents and no ``(n B)^2`` product.

A continuation step solves with the bordered matrix ``[[J, j], [row]]`` (``j = dR/dp``);
it is ``diag(A, 1)`` plus a rank ``m B + 2`` term, so (Woodbury)

    [[J, j], [row]]^{-1} b = y - Z S^{-1} V_b^T y,   y = diag(A, 1)^{-1} b,

with ``Z = diag(A, 1)^{-1} U_b`` and the capacitance ``S = I + V_b^T Z`` of size ``m B + 2``:
``H + 1`` inversions of ``2n x 2n`` blocks and one LU of ``m B + 2`` instead of the LU of
``n B + 1``. It is exact (to rounding) whenever ``A`` is invertible, whatever ``J`` is (the
bordered matrix stays regular through folds, and so does ``S``). :class:`PortJacobian` is the
Jacobian in this form, :class:`PortFactor` the factorisation; both are pytrees, traced by the
compiled continuation corrector.

The free mean slot of a ``free_mean_dof`` (its column of ``J`` the unit vector) is carried by
``A`` (the same column in its mean block) and by ``V^T`` (that column zeroed).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from . import fourier

__all__ = ["CondensedOperator", "port_operator", "PortJacobian", "PortFactor", "check_input_map", "port_basis",
           "as_matrix", "harmonic_major", "coordinate_major"]


class CondensedOperator(NamedTuple):
    """The prepared pieces of the condensed path (a pytree of device arrays).

    **Fields:** `ports` ``(m, n)``: an orthonormal basis ``C`` of the rows of the declared input
    map; when the system's coefficients do not depend on the parameter (else ``None``: built in
    the trace, :func:`port_operator`) the linear operator ``L(w) = A(w) + (P_K + w P_C)(C (x) I)``:
    `mean_stiffness`, `mean_damping` ``(n, n)`` (``Kb``, ``Cb``), `stiffness_ports` ``P_K`` and
    `damping_ports` ``P_C`` ``(n B, m B)``.
    """

    ports: Any
    mean_stiffness: Any = None
    mean_damping: Any = None
    stiffness_ports: Any = None
    damping_ports: Any = None


def port_operator(stiffness, damping, ports, harmonics: int, xp=jnp):
    """``(Kb, Cb, P_K, P_C)`` of :class:`CondensedOperator` from the complex coefficients
    ``(n, n, 2H+1)`` of ``K(s)``, ``C(s)`` and the port basis ``C`` ``(m, n)``: the means, and the
    convolution matrices of ``(K(s) - Kb) C^T`` and ``(C(s) - Cb) C^T (I (x) D_1)`` (``D_1`` the
    derivative at unit frequency), flattened ``(n B, m B)`` with their rows harmonic-major
    (:func:`harmonic_major`)."""
    n, m, b = stiffness.shape[0], ports.shape[0], 2 * harmonics + 1
    right = xp.asarray(ports).T.astype(stiffness.dtype)

    def flat_ports(coefficients):
        c = xp.einsum("ijk,jl->ilk", coefficients, right)
        c = xp.concatenate([0.0 * c[..., :1], c[..., 1:]], axis=-1)  # the mean is A's
        blocks = fourier.convolution_matrix(c, harmonics, xp)  # (n, m, B, B)
        return harmonic_major(blocks, xp)

    # times (I_m (x) D_1) from the right: D_1 acts on each port's block of columns
    damping_ports = times_d1(flat_ports(damping).reshape(n * b, m, b), harmonics, xp).reshape(n * b, m * b)
    return xp.real(stiffness[..., 0]), xp.real(damping[..., 0]), flat_ports(stiffness), damping_ports


def harmonic_major(blocks, xp=jnp):
    """Blocks ``(n, m, B, B)`` (row coordinate, port, row coefficient, column coefficient) as the
    matrix ``(n B, m B)`` with its rows *harmonic-major*: row ``b n + i`` is coordinate ``i``'s
    coefficient ``b`` (the mean block's ``n`` rows, then ``a_k`` and ``b_k`` of every coordinate
    for each ``k``: the rows of ``A``'s diagonal blocks, consecutive)."""
    n, m, b = blocks.shape[0], blocks.shape[1], blocks.shape[2]
    return xp.transpose(blocks, (2, 0, 1, 3)).reshape(n * b, m * b)


def coordinate_major(x, ndof: int):
    """Rows harmonic-major (:func:`harmonic_major`) -> coordinate-major (the unknowns' order)."""
    b = x.shape[0] // ndof
    rest = x.shape[1:]
    return jnp.swapaxes(x.reshape((b, ndof) + rest), 0, 1).reshape(x.shape)


def times_d1(a, harmonics: int, xp):
    """``a @ D_1`` along the last axis (``D_1`` :func:`~hbgear.engine.fourier.derivative_matrix` at
    unit frequency): column ``a_k`` becomes ``-k`` times column ``b_k``, column ``b_k`` ``k``
    times column ``a_k``, column ``a_0`` zero."""
    k = xp.asarray(np.arange(1, harmonics + 1, dtype=float))
    pairs = xp.stack([-k * a[..., 2::2], k * a[..., 1::2]], axis=-1).reshape(a.shape[:-1] + (2 * harmonics,))
    return xp.concatenate([0.0 * a[..., :1], pairs], axis=-1)


class PortFactor(NamedTuple):
    """The factorisation of ``[[J, j], [row]]`` (:meth:`PortJacobian.bordered_factor`)."""

    jacobian: Any  # the PortJacobian's inverses, input map and mask (no A, no U: solve does not read them)
    z: Any  # A^-1 U (nB, mB), rows harmonic-major
    z_column: Any  # A^-1 j (nB,)
    row: Any  # the border row (nB + 1,)
    lu: Any  # LU of the capacitance S (mB + 2)
    perm: Any  # its row permutation (S[perm] = L U)

    def solve(self, b):
        """``[[J, j], [row]]^{-1} b`` (`b` of length ``n B + 1``)."""
        jac = self.jacobian
        mb = self.z.shape[1]
        y = jac.solve_mean(b[:-1])
        last = b[-1]
        t = jnp.concatenate([jac.restrict(y), jnp.stack([last, self.row[:-1] @ y + (self.row[-1] - 1.0) * last])])
        s = _lu_solve(self.lu, self.perm, t)
        zs = coordinate_major(self.z @ s[:mb], jac.inverse_mean.shape[0]) + self.z_column * s[mb]
        return jnp.concatenate([y - zs, (last - s[-1])[None]])


class PortJacobian(NamedTuple):
    """``dR/dz = A + U V^T`` (scaled; module docstring), a pytree.

    **Fields:** `mean` ``(n, n)`` and `blocks` ``(H, 2n, 2n)``: ``A`` at ``k = 0`` (the free mean
    column replaced by the unit column) and on ``(a_k, b_k)`` of all coordinates, ``k >= 1``;
    `inverse_mean`, `inverse_blocks`: their inverses; `ports` ``U`` ``(n B, m B)``, its rows
    harmonic-major (:func:`harmonic_major`: ``A``'s blocks apply to it without transposes); `input_map`
    ``(m, n)``; `keep` ``(n B,)``: 1, 0 at the free mean slot (the column ``V^T`` drops).
    """

    mean: Any
    blocks: Any
    inverse_mean: Any
    inverse_blocks: Any
    ports: Any
    input_map: Any
    keep: Any

    @property
    def _dims(self):
        n, h = self.inverse_mean.shape[0], self.inverse_blocks.shape[0]
        return n, h, 2 * h + 1

    def _per_harmonic(self, mean, blocks, x):
        """``blockdiag(mean, blocks) x`` for `x` ``(n B, ...)`` coordinate-major."""
        n, h, b = self._dims
        rest = x.shape[1:]
        xc = x.reshape((n, b) + rest)
        pairs = jnp.concatenate([jnp.swapaxes(xc[:, 1::2], 0, 1), jnp.swapaxes(xc[:, 2::2], 0, 1)], axis=1)
        solved = jnp.einsum("hij,hj...->hi...", blocks, pairs)  # (H, 2n, ...)
        a, bb = jnp.swapaxes(solved[:, :n], 0, 1), jnp.swapaxes(solved[:, n:], 0, 1)  # (n, H, ...)
        out = jnp.stack([a, bb], axis=2).reshape((n, 2 * h) + rest)
        first = jnp.einsum("ij,j...->i...", mean, xc[:, 0])[:, None]
        return jnp.concatenate([first, out], axis=1).reshape(x.shape)

    def solve_mean(self, x):
        """``A^{-1} x``, `x` ``(n B,)`` or ``(n B, k)``."""
        return self._per_harmonic(self.inverse_mean, self.inverse_blocks, x)

    def restrict(self, x):
        """``V^T x = (C (x) I_B)`` of `x` with the free mean slot zeroed, ``(m B, ...)``."""
        n, _, b = self._dims
        rest = x.shape[1:]
        kept = (x * self.keep.reshape((-1,) + (1,) * len(rest))).reshape((n, b) + rest)
        return jnp.einsum("mi,ib...->mb...", self.input_map, kept).reshape((-1,) + rest)

    def _solve_rows(self, x):
        """``A^{-1} x`` for `x` ``(n B, k)`` with its rows harmonic-major: the mean block on the
        first ``n`` rows, the ``(2n, 2n)`` blocks on the next ``2n`` each, no transposes."""
        n, h, _ = self._dims
        mean = self.inverse_mean @ x[:n]
        rest = jnp.einsum("hij,hjk->hik", self.inverse_blocks, x[n:].reshape(h, 2 * n, -1))
        return jnp.concatenate([mean, rest.reshape(2 * n * h, -1)], axis=0)

    def _restrict_rows(self, x):
        """:meth:`restrict` of `x` ``(n B, k)`` with its rows harmonic-major: ``C diag(keep_b)``
        on each coefficient's ``n`` rows, a batched product that reads `x` in place (the mask
        of the free mean slot is folded into the small ``C``)."""
        n, _, b = self._dims
        m = self.input_map.shape[0]
        c = self.input_map[None] * self.keep.reshape(n, b).T[:, None, :]  # (B, m, n)
        out = jnp.matmul(c, x.reshape(b, n, -1))  # (B, m, k)
        return jnp.swapaxes(out, 0, 1).reshape(m * b, -1)

    def scaled(self, sizes) -> PortJacobian:
        """``J diag(sizes)`` (`sizes` ``(n B,)``, positive): the columns of ``A``'s blocks and
        their inverses' rows, and the mask of ``V^T`` (the continuation in the unknowns
        ``z / sizes``: :func:`hbgear.engine.response.arclength_sizes`)."""
        n, h, b = self._dims
        sc = sizes.reshape(n, b)
        s0 = sc[:, 0]
        pairs = jnp.concatenate([sc[:, 1::2].T, sc[:, 2::2].T], axis=1)  # (H, 2n): a_k then b_k of each coordinate
        return self._replace(mean=self.mean * s0[None, :], blocks=self.blocks * pairs[:, None, :],
                             inverse_mean=self.inverse_mean / s0[:, None],
                             inverse_blocks=self.inverse_blocks / pairs[:, :, None], keep=self.keep * sizes)

    def matvec(self, x):
        """``J x``."""
        n = self.mean.shape[0]
        return self._per_harmonic(self.mean, self.blocks, x) + coordinate_major(self.ports @ self.restrict(x), n)

    def dense(self):
        """``J`` as a matrix (the SVD fallback of a singular bordered system, the Python corrector)."""
        n, _, b = self._dims
        return self.matvec(jnp.eye(n * b))

    def bordered_factor(self, column, row) -> PortFactor:
        """The :class:`PortFactor` of ``[[J, column], [row]]``: ``Z = A^{-1} [U, column]`` and the
        LU of the capacitance ``S`` (module docstring); ``A^{-1} U`` on ``U``'s harmonic-major
        rows (:meth:`_solve_rows`), ``A^{-1} column`` apart (no copy of ``U`` to append it)."""
        n, _, b = self._dims
        z = self._solve_rows(self.ports)  # (nB, mB), rows harmonic-major
        z_column = self.solve_mean(column)
        mb = z.shape[1]
        top = jnp.concatenate([self._restrict_rows(z), self.restrict(z_column)[:, None], jnp.zeros((mb, 1))], axis=1)
        unit = jnp.zeros((1, mb + 2)).at[0, mb + 1].set(1.0)
        row_rows = row[:-1].reshape(n, b).T.reshape(-1)  # the border row's entries harmonic-major
        bottom = jnp.concatenate([row_rows @ z, (row[:-1] @ z_column)[None], (row[-1] - 1.0)[None]])[None]
        capacitance = jnp.eye(mb + 2) + jnp.concatenate([top, unit, bottom], axis=0)
        lu, perm = _lu_factor(capacitance)
        # only what solve reads: a factorisation carried through the continuation's loops is
        # copied there (a third of its bytes were U, unused)
        return PortFactor(self._replace(mean=None, blocks=None, ports=None), z, z_column, row, lu, perm)


def _lu_factor(a):
    """``(lu, perm)``: LAPACK's LU of `a` and its row permutation, made once here so that a solve
    is a gather and two triangular solves. (``jax.scipy.linalg.lu_solve`` turns the pivots into
    the permutation at every call, a loop of one swap per row: at 262 rows it measured 0.14 ms of
    a 0.17 ms solve, one BLAS thread.) The loop is unrolled by 8 (0.065 ms instead of 0.11)."""
    lu, piv = jax.scipy.linalg.lu_factor(a)

    def swap(i, perm):
        j = piv[i]
        return perm.at[i].set(perm[j]).at[j].set(perm[i])

    return lu, jax.lax.fori_loop(0, piv.shape[0], swap, jnp.arange(piv.shape[0], dtype=piv.dtype), unroll=8)


def _lu_solve(lu, perm, b):
    """``a^{-1} b`` from :func:`_lu_factor`'s ``(lu, perm)``."""
    x = jax.lax.linalg.triangular_solve(lu, b[perm][:, None], left_side=True, lower=True, unit_diagonal=True)
    return jax.lax.linalg.triangular_solve(lu, x, left_side=True, lower=False)[:, 0]


def as_matrix(jacobian):
    """A Jacobian as a dense matrix: ``dense()`` of a :class:`PortJacobian`, an array as it is."""
    return jacobian.dense() if hasattr(jacobian, "bordered_factor") else jacobian


def port_basis(matrix, ndof: int):
    """An orthonormal basis ``(m, ndof)`` of the rows of a declared input map (numpy), or ``None``
    when it spans every coordinate (nothing to condense)."""
    c = np.atleast_2d(np.asarray(matrix, dtype=float))
    if c.ndim != 2 or c.shape[1] != ndof or not np.all(np.isfinite(c)):
        raise ValueError(f"input_map(p) has shape {c.shape}: (m, {ndof}) finite values")
    _, sv, vt = np.linalg.svd(c, full_matrices=True)
    rank = int(np.sum(sv > 1e-12 * max(float(sv.max(initial=0.0)), 1e-300)))
    if rank >= ndof:
        return None
    return vt[:rank], vt[rank:]


def check_input_map(system, p, basis=None) -> None:
    """Check a declared ``input_map`` at a probe state (numpy): moving the state along directions
    the map does not see (``C dq = C dq' = 0``) must change the force by the same amount at every
    phase and every state, linearly (``-K_0 dq - C_0 dq'``), and leave the event functions unchanged.

    **Raises:** ``ValueError`` naming the broken promise.
    """
    n = system.ndof
    name = type(system).__name__
    basis = port_basis(system.input_map(p), n) if basis is None else basis
    if basis is None:
        return
    _, null = basis
    rng = np.random.default_rng(1)
    s = np.array([0.0731, 0.3517, 0.8123])
    xs = float(system.displacement_scale)
    vs = xs * float(system.excitation_frequency(p))
    fs = float(system.force_scale)
    dq = null.T @ rng.standard_normal(null.shape[0]) * xs
    dv = null.T @ rng.standard_normal(null.shape[0]) * vs

    def force(q, v):
        return np.asarray(system.force(s, q, v, p, "all", 0.0, np), dtype=float)

    changes = []
    for _ in range(2):
        q = rng.standard_normal((n, s.size)) * 0.5 * xs
        v = rng.standard_normal((n, s.size)) * 0.5 * vs
        base = force(q, v)
        changes.append(force(q + dq[:, None], v + dv[:, None]) - base)
        changes.append(base - force(q - dq[:, None], v - dv[:, None]))
        events = system.event_functions(s, q, v, p, np)
        if events is not None:
            moved = system.event_functions(s, q + dq[:, None], v + dv[:, None], p, np)
            if not np.allclose(np.asarray(moved, float), np.asarray(events, float), rtol=1e-9,
                               atol=1e-9 * xs):
                raise ValueError(f"{name}.input_map: the event functions depend on the state outside C q "
                                 "(declare those directions in the input map, or no input map)")
    ref = changes[0][:, :1]
    scale = fs * 1e-9 + 1e-9 * float(np.max(np.abs(ref)))
    worst = max(float(np.max(np.abs(c - ref))) for c in changes)
    if not worst <= scale:
        raise ValueError(f"{name}.input_map: the force changes by {worst:.3g} N differently with the phase or the "
                         "state along directions with C dq = C dq' = 0 (it must be linear time-invariant there); "
                         "declare those directions in the input map, or no input map")
