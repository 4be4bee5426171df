r"""The condensed path of harmonic balance: Newton and continuation steps of a system whose
coordinates are mostly linear time-invariant, solved on its few *ports* (Woodbury).

A system may declare an ``input_map(p)``, a matrix ``C`` (``m x ndof``), with the promise that the
part of its force that is not linear time-invariant depends on the state only through ``C q``
and ``C q'``:

.. math::  Q(s, q, q') = -K_0 q - C_0 q' + \tilde Q(s, C q, C q')

for some constant ``K_0``, ``C_0`` (bearings, shafts, masses: the LTI structure) and any
``\tilde Q`` (the time-varying, nonlinear mesh). The engine checks the promise at a probe state
(:func:`check_input_map`); it never needs ``K_0``, ``C_0`` themselves.

Then the harmonic-balance Jacobian is, with ``B = 2H+1``,

.. math::  J = A + (O \otimes I_B)\, \tilde U\, (C \otimes I_B),

where ``A`` is the mean Jacobian, block-diagonal per harmonic (``Kb - (k w)^2 M`` on the
diagonal, ``+-k w Cb`` off it, bars the time averages of the periodic stiffness and damping of
``Q_lin`` minus those of the sampled derivatives of ``Q_nl``), ``C`` has orthonormal rows, and
``O`` (``n x r``, orthonormal columns) spans the *outputs*: the coordinates on which the
non-LTI part of the force acts. ``J - A`` vanishes on the directions ``C q = 0`` (the
time-varying and nonlinear terms do not see them and the means in ``A`` see them no more) and
its rows lie in ``range(O)``, so ``\tilde U = (O^T \otimes I)(J - A)(C^T \otimes I)``
(``r B x m B``): ``m`` pointwise directional derivatives of ``Q_nl`` projected on ``O``, and the
convolution matrices of ``O^T K(s) C^T``, ``O^T C(s) C^T`` -- no ``n B`` tangents and no
``(n B)^2`` product. ``O`` is a basis of the system's declared ``output_map`` (a force derived
by virtual work acts on the coordinates it sees: its generalized force is ``C^T`` times
something, so the output map is then the input map), checked at the probe state with the input
map (:func:`check_input_map`); without one, ``O = I``.

A continuation step solves with the bordered matrix ``[[J, j], [row]]`` (``j = dR/dp``);
it is ``diag(A, 1)`` plus a rank ``m B + 2`` term, so (Woodbury)

    [[J, j], [row]]^{-1} b = y - Z S^{-1} V_b^T y,   y = diag(A, 1)^{-1} b,

with ``Z = diag(A, 1)^{-1} U_b`` (never formed) and the capacitance ``S = I + V_b^T Z`` of size
``m B + 2``, whose main block ``I + W \tilde U`` takes ``W = (C \otimes I) A^{-1} (O \otimes I)``,
block-diagonal per harmonic (``2m x 2r`` blocks): ``H + 1`` inversions of ``2n x 2n`` blocks, a
product with ``W`` and one LU of ``m B + 2`` instead of the LU of ``n B + 1``. It is exact (to
rounding) whenever ``A`` is invertible, whatever ``J`` is (the bordered matrix stays regular
through folds, and so does ``S``). :class:`PortJacobian` is the Jacobian in this form,
:class:`PortFactor` the factorisation; both are pytrees, traced by the compiled continuation
corrector.

Port-side vectors and the rows and columns of ``\tilde U`` are *harmonic-major*
(:func:`port_matrix`): entry ``b m + j`` is port ``j``'s coefficient ``b`` -- the mean's ``m``
entries, then ``a_1`` and ``b_1`` of every port, ... -- so that ``W``'s blocks and ``A``'s apply
without transposes.

The free mean slot of a ``free_mean_dof`` (its column of ``J`` the unit vector) is carried by
``A`` (the same column in its mean block) and by ``V^T`` (that column zeroed).
"""

from __future__ import annotations

from functools import lru_cache
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from . import fourier

__all__ = ["CondensedOperator", "port_operator", "PortJacobian", "PortFactor", "check_input_map", "port_basis",
           "output_basis", "as_matrix", "port_matrix", "port_convolution"]


class CondensedOperator(NamedTuple):
    """The prepared pieces of the condensed path (a pytree of device arrays).

    **Fields:** `ports` ``(m, n)``: an orthonormal basis ``C`` of the rows of the declared input
    map; `outputs` ``(r, n)``: ``O^T`` (:func:`output_basis`: of the declared output map, or the
    identity); when the
    system's coefficients do not depend on the parameter (else ``None``: built in the trace,
    :func:`port_operator`) the linear operator
    ``L(w) = A(w) + (O (x) I)(P_K + w P_C)(C (x) I)``: `mean_stiffness`, `mean_damping`
    ``(n, n)`` (``Kb``, ``Cb``), `stiffness_ports` ``P_K`` and `damping_ports` ``P_C``
    ``(r B, m B)`` (:func:`port_matrix`), and the complex coefficients they are made of,
    `stiffness_coefficients` and `damping_coefficients` ``(r, m, B)`` (``O^T K(s) C^T`` and
    ``O^T C(s) C^T``, the means zeroed: :func:`port_convolution` of them gives ``P_K`` and ``P_C``).
    """

    ports: Any
    outputs: Any
    mean_stiffness: Any = None
    mean_damping: Any = None
    stiffness_ports: Any = None
    damping_ports: Any = None
    stiffness_coefficients: Any = None
    damping_coefficients: Any = None


def port_operator(stiffness, damping, ports, outputs, harmonics: int, xp=jnp):
    """``(Kb, Cb, P_K, P_C, c_K, c_C)`` of :class:`CondensedOperator` from the complex
    coefficients ``(n, n, 2H+1)`` of ``K(s)``, ``C(s)``, the port basis ``C`` ``(m, n)`` and the
    outputs ``O^T`` ``(r, n)``: the means, the convolution matrices of ``O^T (K(s) - Kb) C^T`` and
    ``O^T (C(s) - Cb) C^T (I (x) D_1)`` (``D_1`` the derivative at unit frequency) as
    :func:`port_matrix` ``(r B, m B)``, and those coefficients ``(r, m, B)``."""
    right = xp.asarray(ports).T.astype(stiffness.dtype)
    left = xp.asarray(outputs).astype(stiffness.dtype)

    def projected(coefficients):
        c = xp.einsum("ri,ijk,jl->rlk", left, coefficients, right)
        return xp.concatenate([0.0 * c[..., :1], c[..., 1:]], axis=-1)  # the mean is A's

    c_k, c_c = projected(stiffness), projected(damping)
    return (xp.real(stiffness[..., 0]), xp.real(damping[..., 0]), port_convolution(c_k, harmonics, xp=xp),
            port_convolution(c_c, harmonics, derivative=True, xp=xp), c_k, c_c)


def port_matrix(blocks, xp=jnp):
    """Blocks ``(r, m, B, B)`` (output, port, row coefficient, column coefficient) as the matrix
    ``(r B, m B)``, harmonic-major on both sides: row ``b r + i`` is output ``i``'s coefficient
    ``b``, column ``d m + j`` port ``j``'s coefficient ``d``."""
    r, m, b = blocks.shape[0], blocks.shape[1], blocks.shape[2]
    return xp.transpose(blocks, (2, 0, 3, 1)).reshape(b * r, b * m)


@lru_cache(maxsize=16)
def _port_gather(outputs: int, ports: int, harmonics: int, derivative: bool):
    """:func:`port_convolution`'s tables: :func:`hbgear.engine.fourier.convolution_gather` laid out
    as :func:`port_matrix` ``(2, r B, m B)``, the index into the flattened ``(r, m, 2B)``."""
    index, factor = fourier.convolution_gather(harmonics, derivative)  # (2, B, B)
    b = index.shape[1]
    i = np.arange(outputs)[None, None, :, None, None]
    j = np.arange(ports)[None, None, None, None, :]
    flat = (i * ports + j) * (2 * b) + index[:, :, None, :, None]  # (2, B, r, B, m)
    flat = flat.reshape(2, b * outputs, b * ports).astype(np.int32)
    factor = np.broadcast_to(factor[:, :, None, :, None], (2, b, outputs, b, ports)).reshape(flat.shape)
    return flat, np.ascontiguousarray(factor)


def port_convolution(coefficients, harmonics: int, derivative: bool = False, xp=jnp):
    """:func:`port_matrix` of the convolution matrices (:func:`hbgear.engine.fourier.convolution_matrix`,
    times ``D_1`` with `derivative`) of complex `coefficients` ``(r, m, 2H+1)``: ``(r B, m B)``,
    made by two gathers (:func:`hbgear.engine.fourier.convolution_gather`) in one pass."""
    r, m = coefficients.shape[:2]
    index, factor = _port_gather(r, m, harmonics, derivative)
    v = xp.concatenate([xp.real(coefficients), xp.imag(coefficients)], axis=-1).reshape(-1)
    if xp is np:
        return v[index[0]] * factor[0] + v[index[1]] * factor[1]
    return (v.at[index[0]].get(mode="promise_in_bounds") * factor[0]
            + v.at[index[1]].get(mode="promise_in_bounds") * factor[1])


def times_d1(a, harmonics: int, xp):
    """``a @ D_1`` along the last axis (``D_1`` :func:`~hbgear.engine.fourier.derivative_matrix` at
    unit frequency): column ``a_k`` becomes ``-k`` times column ``b_k``, column ``b_k`` ``k``
    times column ``a_k``, column ``a_0`` zero."""
    k = xp.asarray(np.arange(1, harmonics + 1, dtype=float))
    pairs = xp.stack([-k * a[..., 2::2], k * a[..., 1::2]], axis=-1).reshape(a.shape[:-1] + (2 * harmonics,))
    return xp.concatenate([0.0 * a[..., :1], pairs], axis=-1)


class PortFactor(NamedTuple):
    """The factorisation of ``[[J, j], [row]]`` (:meth:`PortJacobian.bordered_factor`)."""

    jacobian: Any  # the PortJacobian without A (its inverses, U~, the maps and the mask)
    z_column: Any  # A^-1 j (nB,)
    row: Any  # the border row (nB + 1,)
    lu: Any  # LU of the capacitance S (mB + 2)
    perm: Any  # its row permutation (S[perm] = L U)

    def solve(self, b):
        """``[[J, j], [row]]^{-1} b`` (`b` of length ``n B + 1``)."""
        jac = self.jacobian
        mb = jac.ports.shape[1]
        y = jac.solve_mean(b[:-1])
        last = b[-1]
        t = jnp.concatenate([jac.restrict(y), jnp.stack([last, self.row[:-1] @ y + (self.row[-1] - 1.0) * last])])
        s = lu_solve(self.lu, self.perm, t)
        correction = jac.solve_mean(jac.expand(jac.ports @ s[:mb])) + self.z_column * s[mb]
        return jnp.concatenate([y - correction, (last - s[-1])[None]])


class PortJacobian(NamedTuple):
    """``dR/dz = A + (O (x) I) U~ (C (x) I) diag(keep)`` (scaled; module docstring), a pytree.

    **Fields:** `mean` ``(n, n)`` and `blocks` ``(H, 2n, 2n)``: ``A`` at ``k = 0`` (the free mean
    column replaced by the unit column) and on ``(a_k, b_k)`` of all coordinates, ``k >= 1``;
    `inverse_mean`, `inverse_blocks`: their inverses; `ports` ``U~`` ``(r B, m B)``
    (:func:`port_matrix`); `input_map` ``C`` ``(m, n)``; `output_map` ``O^T`` ``(r, n)``;
    `keep` ``(n B,)``: 1, 0 at the free mean slot (the column ``V^T`` drops).
    """

    mean: Any
    blocks: Any
    inverse_mean: Any
    inverse_blocks: Any
    ports: Any
    input_map: Any
    output_map: Any
    keep: Any

    @property
    def _dims(self):
        n, h = self.inverse_mean.shape[0], self.inverse_blocks.shape[0]
        return n, h, 2 * h + 1

    def _per_harmonic(self, mean, blocks, x):
        """``blockdiag(mean, blocks) x`` for `x` ``(n B, ...)`` coordinate-major: harmonic-major, the
        coefficients ``a_k``, ``b_k`` of all coordinates are consecutive rows, one block's input."""
        n, h, b = self._dims
        rest = x.shape[1:]
        xh = jnp.swapaxes(x.reshape((n, b) + rest), 0, 1)  # (B, n, ...)
        first = jnp.einsum("ij,j...->i...", mean, xh[0])
        pairs = jnp.einsum("hij,hj...->hi...", blocks, xh[1:].reshape((h, 2 * n) + rest))
        out = jnp.concatenate([first[None], pairs.reshape((2 * h, n) + rest)], axis=0)
        return jnp.swapaxes(out, 0, 1).reshape(x.shape)

    def solve_mean(self, x):
        """``A^{-1} x``, `x` ``(n B,)`` or ``(n B, k)`` coordinate-major."""
        return self._per_harmonic(self.inverse_mean, self.inverse_blocks, x)

    def restrict(self, x):
        """``V^T x = (C (x) I_B)`` of `x` (coordinate-major) with the free mean slot zeroed,
        harmonic-major ``(m B, ...)``."""
        n, _, b = self._dims
        rest = x.shape[1:]
        kept = (x * self.keep.reshape((-1,) + (1,) * len(rest))).reshape((n, b) + rest)
        return jnp.einsum("mi,ib...->bm...", self.input_map, kept).reshape((-1,) + rest)

    def expand(self, v):
        """``(O (x) I_B) v``: `v` ``(r B, ...)`` harmonic-major to ``(n B, ...)`` coordinate-major."""
        n, _, b = self._dims
        rest = v.shape[1:]
        vb = v.reshape((b, self.output_map.shape[0]) + rest)
        return jnp.einsum("ri,br...->ib...", self.output_map, vb).reshape((n * b,) + rest)

    def scaled(self, sizes) -> PortJacobian:
        """``J diag(sizes)`` (`sizes` ``(n B,)``, positive): the columns of ``A``'s blocks and
        their inverses' rows, and the mask of ``V^T`` (the continuation in the unknowns
        ``z / sizes``: :func:`hbgear.engine.metric.arclength_sizes`)."""
        n, h, b = self._dims
        sc = sizes.reshape(n, b)
        s0 = sc[:, 0]
        pairs = jnp.concatenate([sc[:, 1::2].T, sc[:, 2::2].T], axis=1)  # (H, 2n): a_k then b_k of each coordinate
        return self._replace(mean=self.mean * s0[None, :], blocks=self.blocks * pairs[:, None, :],
                             inverse_mean=self.inverse_mean / s0[:, None],
                             inverse_blocks=self.inverse_blocks / pairs[:, :, None], keep=self.keep * sizes)

    def matvec(self, x):
        """``J x``."""
        return self._per_harmonic(self.mean, self.blocks, x) + self.expand(self.ports @ self.restrict(x))

    def dense(self):
        """``J`` as a matrix (the SVD fallback of a singular bordered system, the Python corrector)."""
        n, _, b = self._dims
        return self.matvec(jnp.eye(n * b))

    def _capacitance_blocks(self):
        """``W = V^T A^{-1} (O (x) I)`` per coefficient: ``(m, r)`` for the mean and ``(H, 2m, 2r)``
        on ``(a_k, b_k)``, the mask of the free mean slot folded into ``C``."""
        n, h, b = self._dims
        c, o = self.input_map, self.output_map.T  # (m, n), (n, r)
        keep = self.keep.reshape(n, b)
        w0 = (c * keep[:, 0][None]) @ self.inverse_mean @ o
        x = jnp.concatenate([self.inverse_blocks[:, :, :n] @ o, self.inverse_blocks[:, :, n:] @ o], axis=2)  # (H, 2n, 2r)
        top = jnp.einsum("mi,hi,hir->hmr", c, keep[:, 1::2].T, x[:, :n])
        bottom = jnp.einsum("mi,hi,hir->hmr", c, keep[:, 2::2].T, x[:, n:])
        return w0, jnp.concatenate([top, bottom], axis=1)

    def _row_through(self, row):
        """``row^T A^{-1} (O (x) I)`` (`row` ``(n B,)`` coordinate-major), harmonic-major ``(r B,)``."""
        n, h, b = self._dims
        o = self.output_map.T
        rc = row.reshape(n, b)
        first = (rc[:, 0] @ self.inverse_mean) @ o
        pairs = jnp.concatenate([rc[:, 1::2].T, rc[:, 2::2].T], axis=1)  # (H, 2n)
        through = jnp.einsum("hi,hij->hj", pairs, self.inverse_blocks)  # (H, 2n)
        return jnp.concatenate([first, jnp.concatenate([through[:, :n] @ o, through[:, n:] @ o], axis=1).reshape(-1)])

    def bordered_factor(self, column, row) -> PortFactor:
        """The :class:`PortFactor` of ``[[J, column], [row]]``: the LU of the capacitance ``S``
        (module docstring), its main block ``I + W U~`` by ``W``'s small blocks, its border from
        ``A^{-1} column`` and ``row^T A^{-1}``; no ``A^{-1} U`` (the solve applies ``A^{-1}``
        after ``U~``)."""
        n, h, _ = self._dims
        r = self.output_map.shape[0]
        u = self.ports
        mb = u.shape[1]
        w0, wk = self._capacitance_blocks()
        main = jnp.concatenate([w0 @ u[:r], jnp.einsum("hij,hjk->hik", wk, u[r:].reshape(h, 2 * r, mb)).reshape(-1, mb)])
        z_column = self.solve_mean(column)
        top = jnp.concatenate([main, self.restrict(z_column)[:, None], jnp.zeros((mb, 1))], axis=1)
        unit = jnp.zeros((1, mb + 2)).at[0, mb + 1].set(1.0)
        bottom = jnp.concatenate([self._row_through(row[:-1]) @ u, (row[:-1] @ z_column)[None], (row[-1] - 1.0)[None]])
        capacitance = jnp.eye(mb + 2) + jnp.concatenate([top, unit, bottom[None]], axis=0)
        lu, perm = lu_factor(capacitance)
        # only what solve reads: a factorisation carried through the continuation's loops is copied there
        return PortFactor(self._replace(mean=None, blocks=None), z_column, row, lu, perm)


def lu_factor(a):
    """``(lu, perm)``: LAPACK's LU of ``a^T`` and its row permutation (``a^T[perm] = L U``), for
    :func:`lu_solve`.

    The transpose, not `a`: LAPACK wants its matrix column-major, and ``a^T`` of a row-major `a`
    is `a`'s own buffer read column-major, where the LU of `a` itself starts with a transposing
    copy (at 262 rows 0.12 ms, a fifth of the factorisation). The permutation is made once here
    so that a solve is two triangular solves and a scatter."""
    lu, _, perm = jax.lax.linalg.lu(jnp.transpose(a))
    return lu, perm


def lu_solve(lu, perm, b):
    """``a^{-1} b`` from :func:`lu_factor`'s ``(lu, perm)``: ``a = U^T L^T P``, so
    ``P x = L^{-T} U^{-T} b``."""
    y = jax.lax.linalg.triangular_solve(lu, jnp.asarray(b)[:, None], left_side=True, lower=False,
                                        transpose_a=True)
    y = jax.lax.linalg.triangular_solve(lu, y, left_side=True, lower=True, unit_diagonal=True, transpose_a=True)
    return jnp.zeros_like(y[:, 0]).at[perm].set(y[:, 0])


def as_matrix(jacobian):
    """A Jacobian as a dense matrix: ``dense()`` of a :class:`PortJacobian`, an array as it is."""
    return jacobian.dense() if hasattr(jacobian, "bordered_factor") else jacobian


def port_basis(matrix, ndof: int, what: str = "input_map"):
    """``(basis, complement)``: an orthonormal basis ``(m, ndof)`` of the rows of a declared input
    (or output) map and one of the rest (numpy), or ``None`` when there is no map or it spans
    every coordinate (nothing to condense)."""
    if matrix is None:
        return None
    c = np.atleast_2d(np.asarray(matrix, dtype=float))
    if c.ndim != 2 or c.shape[1] != ndof or not np.all(np.isfinite(c)):
        raise ValueError(f"{what}(p) has shape {c.shape}: (m, {ndof}) finite values")
    _, sv, vt = np.linalg.svd(c, full_matrices=True)
    rank = int(np.sum(sv > 1e-12 * max(float(sv.max(initial=0.0)), 1e-300)))
    if rank >= ndof:
        return None
    return vt[:rank], vt[rank:]


def output_basis(system, p) -> np.ndarray:
    """``O^T`` ``(r, n)`` of the module docstring (numpy): an orthonormal basis of the rows of the
    declared ``output_map``, or the identity when there is none or it spans every coordinate."""
    basis = port_basis(system.output_map(p), system.ndof, "output_map")
    return np.eye(system.ndof) if basis is None else basis[0]


def _probe_changes(system, p, seed, directions, outside):
    """Central changes of ``outside(Q)`` for a random move ``(dq, dq')`` in the span of the rows
    of `directions`, at three phases and two random states (numpy): ``(worst deviation from the
    first change, its tolerance, [(event functions before, after the move)] per state)`` (the
    list empty without events)."""
    n = system.ndof
    rng = np.random.default_rng(seed)
    s = np.array([0.0731, 0.3517, 0.8123])
    xs = float(system.displacement_scale)
    vs = xs * float(system.excitation_frequency(p))
    dq = directions.T @ rng.standard_normal(directions.shape[0]) * xs
    dv = directions.T @ rng.standard_normal(directions.shape[0]) * vs

    def force(q, v):
        return outside(np.asarray(system.force(s, q, v, p, "all", 0.0, np), dtype=float))

    changes, events = [], []
    for _ in range(2):
        q = rng.standard_normal((n, s.size)) * 0.5 * xs
        v = rng.standard_normal((n, s.size)) * 0.5 * vs
        base = force(q, v)
        changes.append(force(q + dq[:, None], v + dv[:, None]) - base)
        changes.append(base - force(q - dq[:, None], v - dv[:, None]))
        before = system.event_functions(s, q, v, p, np)
        if before is not None:
            events.append((before, system.event_functions(s, q + dq[:, None], v + dv[:, None], p, np)))
    ref = changes[0][:, :1]
    scale = float(system.force_scale) * 1e-9 + 1e-9 * float(np.max(np.abs(ref), initial=0.0))
    worst = max(float(np.max(np.abs(c - ref), initial=0.0)) for c in changes)
    return worst, scale, events


def check_input_map(system, p, basis=None) -> None:
    """Check a declared ``input_map`` and ``output_map`` at probe states (numpy): moving the state
    along directions the input map does not see (``C dq = C dq' = 0``) must change the force by
    the same amount at every phase and every state, linearly (``-K_0 dq - C_0 dq'``), and leave
    the event functions unchanged; moving it in any direction must change the force's part
    off the output map's rows (``(I - O O^T) Q``) in the same way.

    **Raises:** ``ValueError`` naming the broken promise.
    """
    n = system.ndof
    name = type(system).__name__
    basis = port_basis(system.input_map(p), n) if basis is None else basis
    if basis is None:
        return
    worst, scale, events = _probe_changes(system, p, 1, basis[1], lambda f: f)
    for before, after in events:
        if not np.allclose(np.asarray(after, float), np.asarray(before, float), rtol=1e-9,
                           atol=1e-9 * float(system.displacement_scale)):
            raise ValueError(f"{name}.input_map: the event functions depend on the state outside C q "
                             "(declare those directions in the input map, or no input map)")
    if not worst <= scale:
        raise ValueError(f"{name}.input_map: the force changes by {worst:.3g} N differently with the phase or the "
                         "state along directions with C dq = C dq' = 0 (it must be linear time-invariant there); "
                         "declare those directions in the input map, or no input map")
    outputs = port_basis(system.output_map(p), n, "output_map")
    if outputs is None:
        return
    off = outputs[1]
    worst, scale, _ = _probe_changes(system, p, 2, np.eye(n), lambda f: off @ f)
    if not worst <= scale:
        raise ValueError(f"{name}.output_map: the force off its rows changes by {worst:.3g} N differently with the "
                         "phase or the state (it must be linear time-invariant there); declare every coordinate "
                         "the mesh acts on, or no output map")
