r"""The structured path of harmonic balance: the residual and its Jacobian as FFT products,
Newton steps by preconditioned GMRES, no ``(size x size)`` array (many harmonics).

With ``X`` the coefficients (``n`` coordinates, ``B = 2H+1`` each), ``E_M``/``P_M`` synthesis
on / projection from ``M > 4H`` uniform samples, ``D1`` the derivative at unit frequency
(:func:`hbgear.engine.fourier.differentiate`, no matrix) and ``w`` the base frequency, the
linear periodic part of :mod:`hbgear.engine.hb` is applied as

    L(w) X = P_M [K(t) E_M X + w C(t) E_M D1 X] + w^2 (M (x) D1^2) X

with ``K(t)``, ``C(t)`` the trigonometric polynomials of degree ``2H`` of the exact
coefficients ``p_0 .. p_2H`` (the entries of the dense convolution matrices): the product
has degree ``3H``, so ``M > 4H`` samples project it onto the harmonics ``<= H`` without
aliasing, and this *is* ``(K_conv + w C_conv D1 + w^2 M D1^2) X`` to rounding, in
``O(n^2 M log M)`` instead of ``O(size^2)``. The coefficients themselves come from the same
quadrature as the dense path's by chirp transforms (:func:`~hbgear.engine.quadrature.lattice_coefficients`)
instead of an ``(orders x nodes)`` kernel.

The Jacobian of the AFT term is ``P diag(G) E`` (``G`` the pointwise derivatives of ``Q_nl``
at the ``N`` samples, plus the jump corrections at the breakpoints), applied as such:

    J V = (xs/fs) [L(w) V' - P_N (G_q E_N V' + G_v E_N w D1 V') - delta^T (J_q at_c V' + J_v at_c w D1 V')] + e_k V_k

(``V'`` the direction with the free mean slot ``k`` zeroed, ``J_*`` the jumps of ``G`` at the
breakpoints): exactly the derivative of the residual, the dense Jacobian's product to
rounding. **Preconditioner** ``Jb``: the Jacobian's couplings between harmonics at most
:data:`~hbgear.engine.banded.BAND` apart (:mod:`hbgear.engine.banded`: from the Fourier
coefficients of ``K - G_q`` and ``C - G_v``, block-tridiagonal in groups of harmonics, factored
once per linearisation in ``O(H n^3 BAND^2)``). GMRES (:mod:`hbgear.engine.krylov`) solves
``J s = -R`` with it on the right, to the relative residual the Newton iteration asks for
(:func:`hbgear.engine.newton.newton`: inexact Newton, Eisenstat--Walker forcing terms). On the
NLTV pair at 200 rpm, H = 512, N = 4096, a solve to 1e-10 takes 18 products (5.6 ms) where the
mean Jacobian alone (one block per harmonic, the band's ``BAND = 0`` without the ``g_{2k}``
terms) took 65 (16.2 ms).

The harmonic-balance object decides by size (:attr:`hbgear.engine.hb.HarmonicBalance.structured`).

**Continuation.** The compiled corrector (:mod:`hbgear.engine.continuation.compiled`) takes the
Jacobian as a :class:`KrylovJacobian` (the same products) and solves each bordered system
``[[J, dR/dp], [row]]`` by GMRES inside its program (:func:`~hbgear.engine.krylov.gmres`,
no return to Python per product), right-preconditioned by ``Jb`` bordered with the same column
and row (:class:`KrylovFactor`), to :data:`BORDERED_RTOL`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import partial
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from . import banded, fourier
from .arrays import device_array
from .krylov import KrylovInfo, gmres
from .persistent import persistent
from .typed_jit import typed_jit

__all__ = ["StructuredOperator", "Linearization", "StructuredJacobian", "KrylovJacobian", "KrylovFactor",
           "prepare_structured", "product_samples", "linear_response", "linearize", "linearization"]

#: GMRES settings of a Newton step: Krylov vectors kept before a restart, products at most.
RESTART = 80
MAX_PRODUCTS = 800


class StructuredOperator(NamedTuple):
    """The prepared pieces of the structured path (a pytree of device arrays).

    **Fields:** `lattice` the :class:`~hbgear.engine.quadrature.LatticeRule` of the quadrature;
    when the system's coefficients do not depend on the parameter (else ``None``): `stiffness`,
    `damping` the complex coefficients ``(n, n, 2H+1)`` of ``K(s)``, ``C(s)``, their samples
    `stiffness_samples`, `damping_samples` ``(n, n, M)`` on the product grid
    (:func:`product_samples`), and `forcing` the :class:`~hbgear.engine.hb.ForcingPieces` (or
    ``None``).
    """

    lattice: Any
    stiffness: Any = None
    damping: Any = None
    stiffness_samples: Any = None
    damping_samples: Any = None
    forcing: Any = None


class Linearization(NamedTuple):
    """What a Jacobian product needs at one point (a pytree): the base frequency `w`, the mass
    matrix `mass`, the samples `stiffness`, `damping` ``(n, n, M)``, the derivative samples
    `derivatives` ``(1|2, n, n, N + 2C)`` (``None`` for a linear system), the jump layout's
    `at_c`, `weight`, `delta`, the scale ``xs / fs`` and the preconditioner's factorisation
    `band` (:class:`~hbgear.engine.banded.BandFactor`)."""

    w: Any
    mass: Any
    stiffness: Any
    damping: Any
    derivatives: Any
    at_c: Any
    weight: Any
    delta: Any
    scale: Any
    band: Any


def product_samples(harmonics: int) -> int:
    """``M``: the smallest FFT-friendly length above ``4H`` (exact products of degree ``2H`` by ``H``)."""
    import scipy.fft  # here, not at import: the curves of few harmonics never need it (0.1 s of every run)

    return scipy.fft.next_fast_len(4 * harmonics + 1, real=True)


def prepare_structured(hb, system, p, lattice, device_lattice) -> StructuredOperator:
    """The :class:`StructuredOperator` of `system` for the discretisation `hb`: the periodic
    coefficients by the lattice quadrature (numpy, once) when they do not depend on the parameter.

    **Arguments:** `lattice`, `device_lattice`: the rule in numpy and as device arrays.
    """
    if not system.coefficients_independent_of_parameter:
        return StructuredOperator(device_lattice)
    _, stiffness, damping = hb._periodic_coefficients(system, p, lattice, np)
    samples = [_samples(c, hb.harmonics, np) for c in (stiffness, damping)]
    return StructuredOperator(device_lattice, *jax.device_put((stiffness, damping, *samples)),
                              hb._forcing_pieces(system, lattice))


def _samples(coefficients, harmonics: int, xp=jnp):
    """``K(t_j)`` on the product grid from its complex coefficients ``p_0 .. p_2H`` (``Im p_0`` dropped)."""
    real = fourier.coefficients_to_real(coefficients, 2 * harmonics, xp)
    return fourier.synthesize(real, 2 * harmonics, product_samples(harmonics), xp)


def _operator_samples(hb, system, p, prepared):
    """``(F, K(t_j), C(t_j))``: the forcing vector and the coefficient samples (kept, or by quadrature)."""
    pieces = prepared.structured
    forcing, stiffness, damping = hb._coefficients(system, p, prepared)
    if pieces.stiffness_samples is not None:
        return forcing, pieces.stiffness_samples, pieces.damping_samples
    return forcing, _samples(stiffness, hb.harmonics), _samples(damping, hb.harmonics)


def _apply_linear(hb, x, w, mass, stiffness, damping):
    """``L(w) x`` in SI: ``P_M (K E_M x + w C E_M D1 x) + w^2 M D1^2 x``, `x` ``(n, B)``."""
    H, samples = hb.harmonics, stiffness.shape[-1]
    v1 = fourier.differentiate(x, H, 1.0, jnp)
    u = jnp.einsum("ijt,jt->it", stiffness, fourier.synthesize(x, H, samples, jnp))
    u = u + w * jnp.einsum("ijt,jt->it", damping, fourier.synthesize(v1, H, samples, jnp))
    return fourier.project(u, H, jnp) + w**2 * (mass @ fourier.differentiate(v1, H, 1.0, jnp))


def linear_response(hb, x, p, system, prepared):
    """``L x - F`` in SI on the structured path (the dense path's :meth:`~hbgear.engine.hb.HarmonicBalance._linear_response`)."""
    forcing, stiffness, damping = _operator_samples(hb, system, p, prepared)
    w = hb.base_frequency(system, p)
    lx = _apply_linear(hb, x.reshape(hb.ndof, hb.block), w, system.mass_matrix(p, jnp), stiffness, damping)
    return lx.reshape(hb.size) - forcing


def _apply_nonlinear(hb, x, lin: Linearization):
    """``d(P Q_nl)/dx x`` in SI: ``P_N (G_q E_N x + G_v E_N w D1 x)`` plus the jump terms, `x` ``(n, B)``."""
    H, N = hb.harmonics, hb.samples
    directions = [fourier.differentiate(x, H, lin.w, jnp)]
    if lin.derivatives.shape[0] == 2:
        directions.insert(0, x)
    u, jumps = 0.0, 0.0
    for g, d in zip(lin.derivatives, directions):
        u = u + jnp.einsum("ijt,jt->it", g[..., :N], fourier.synthesize(d, H, N, jnp))
        count = lin.weight.shape[0]
        jump = (g[..., N : N + count] - g[..., N + count :]) * lin.weight  # (n, n, C)
        jumps = jumps + jnp.einsum("ijc,jc->ic", jump, d @ lin.at_c.T)
    return fourier.project(u, H, jnp) + jumps @ lin.delta


def _band_factor(hb, lin: Linearization, free_slot) -> banded.BandFactor:
    """The band preconditioner (:mod:`hbgear.engine.banded`) of the linearisation: the
    coefficients of ``K - G_q`` and ``C - G_v`` from their samples (the jump terms left out)."""
    H, N = hb.harmonics, hb.samples
    stiffness, damping = banded.coefficients(lin.stiffness, H), banded.coefficients(lin.damping, H)
    if lin.derivatives is not None:
        g = banded.coefficients(lin.derivatives[..., :N], H)
        damping = damping - g[-1]
        stiffness = stiffness - g[0] if g.shape[0] == 2 else stiffness
    blocks = banded.band_blocks(stiffness, damping, lin.w, lin.mass, lin.scale, H, free_slot)
    return banded.factor_band(blocks)


def _kept_linearization(function):
    """``typed_jit`` with the ``HarmonicBalance`` static, its traced programs kept on disk when a
    directory is enabled (:mod:`hbgear.engine.persistent`)."""
    return persistent(typed_jit(function, static_argnums=0), "structured-linearize",
                      "engine.structured._linearize_jit", static_argnums=0)


@_kept_linearization
def _linearize_jit(hb, z, p, system, prepared):
    return linearization(hb, z, p, system, prepared)


def linearization(hb, z, p, system, prepared) -> Linearization:
    """The :class:`Linearization` at ``(z, p)`` (traceable): derivative samples, coefficient
    samples, the band preconditioner's factorisation."""
    x, extra = hb._split(system, z)
    _, stiffness, damping = _operator_samples(hb, system, p, prepared)
    derivatives = at_c = weight = delta = None
    if not system.is_linear:
        derivatives, (_, at_c, weight, delta) = hb._nonlinear_derivatives(x, extra, p, system, prepared.jumps)
    # the scalars as float64 arrays, not weakly typed: a linearisation loaded from disk
    # (hbgear.engine.persistent) returns them typed, and a traced one must give the solve's
    # program the same argument types (else the next process exports the solve again)
    w, scale = (jnp.asarray(v, dtype=jnp.float64) for v in (hb.base_frequency(system, p),
                                                           system.displacement_scale / system.force_scale))
    lin = Linearization(w, system.mass_matrix(p, jnp), stiffness, damping, derivatives, at_c, weight, delta, scale,
                        None)
    return lin._replace(band=_band_factor(hb, lin, system.free_mean_dof))


def _product(hb, free_slot, lin: Linearization, v):
    """``J v`` (scaled) at the linearisation `lin`."""
    n, B = hb.ndof, hb.block
    slot = None if free_slot is None else free_slot * B
    direction = v if slot is None else v.at[slot].set(0.0)
    x = direction.reshape(n, B)
    out = _apply_linear(hb, x, lin.w, lin.mass, lin.stiffness, lin.damping)
    if lin.derivatives is not None:
        out = out - _apply_nonlinear(hb, x, lin)
    out = out.reshape(hb.size) * lin.scale
    return out if slot is None else out.at[slot].add(v[slot])


def _precondition(hb, band: banded.BandFactor, v):
    """``P^{-1} v``: the band of the Jacobian (:mod:`hbgear.engine.banded`) solved."""
    n, H = hb.ndof, hb.harmonics
    return banded.from_groups(banded.solve_band(band, banded.to_groups(v, n, H)), n, H)


@partial(jax.jit, static_argnums=(0, 1))
def _product_jit(hb, free_slot, lin, v):
    return _product(hb, free_slot, lin, v)


def _solve(hb, free_slot, restart, max_products, lin, b, rtol):
    return gmres(lambda v: _product(hb, free_slot, lin, v), b, precondition=lambda v: _precondition(hb, lin.band, v),
                 rtol=rtol, restart=restart, max_products=max_products)


#: A Newton step's GMRES solve, one compiled program per (discretisation, settings), its traced
#: form kept on disk like the linearisation's (tracing and lowering it took ~0.26 s a process).
_solve_jit = persistent(typed_jit(_solve, static_argnums=(0, 1, 2, 3)), "structured-solve",
                        "engine.structured._solve_jit", static_argnums=(0, 1, 2, 3))


class StructuredJacobian:
    """``dR/dz`` at one point as products and preconditioned GMRES solves (:func:`linearize`).

    **Methods:** :meth:`matvec` ``v -> J v``; :meth:`solve` ``(b, rtol) -> (x, KrylovInfo)``
    with ``||b - J x|| <= rtol ||b||`` (GMRES preconditioned by the band ``Jb``).
    """

    def __init__(self, hb, free_slot, lin: Linearization):
        self.hb, self.free_slot, self.linearization = hb, free_slot, lin

    def matvec(self, v) -> np.ndarray:
        return np.asarray(_product_jit(self.hb, self.free_slot, self.linearization, device_array(v)))

    def solve(self, b, rtol: float) -> tuple[np.ndarray, KrylovInfo]:
        """GMRES(:data:`RESTART`) with the band preconditioner on the right, at most
        :data:`MAX_PRODUCTS` products, in one compiled call; the best iterate and how far it got."""
        x, info = _solve_jit(self.hb, self.free_slot, RESTART, MAX_PRODUCTS, self.linearization, device_array(b),
                             float(rtol))
        x, info = jax.device_get((x, info))
        return np.asarray(x), KrylovInfo(bool(info.converged), int(info.iterations), float(info.relative_residual))


def linearize(hb, z, p, system, prepared):
    """``(R, J)`` at ``(z, p)`` on the structured path: the residual (device array; the compiled
    residual the line search uses too) and the :class:`StructuredJacobian` (derivative samples,
    the band preconditioner's factorisation: one compiled evaluation)."""
    r = hb._residual_jit(z, p, system, prepared)
    return r, StructuredJacobian(hb, system.free_mean_dof, _linearize_jit(hb, z, p, system, prepared))


# ----------------------------------------------------------------------------- the continuation's form

#: The continuation corrector's bordered solves (:meth:`KrylovFactor.solve`, inside its compiled
#: program): GMRES to this relative residual, at most :data:`BORDERED_MAX_PRODUCTS` products in
#: cycles of :data:`RESTART`; a solve that stops above :data:`BORDERED_USABLE_RTOL` gives NaN
#: (the corrector then reports a failed step or, for the tangent, takes the SVD fallback).
BORDERED_RTOL = 1e-10
BORDERED_MAX_PRODUCTS = 400
BORDERED_USABLE_RTOL = 1e-6


@partial(jax.tree_util.register_dataclass, data_fields=["linearization", "sizes"],
         meta_fields=["hb", "free_slot"])
@dataclass(frozen=True)
class KrylovJacobian:
    """``dR/dz diag(sizes)`` at one point as products (a pytree, traced by the compiled
    continuation corrector, :mod:`hbgear.engine.continuation.compiled`): the structured path's
    :class:`Linearization` with the interface of :class:`~hbgear.engine.condensed.PortJacobian`
    (:meth:`bordered_factor`, :meth:`dense`, :meth:`scaled`).

    **Fields:** `hb` (static), `free_slot` (static: the free mean coordinate or ``None``),
    `linearization`, `sizes` ``(size,)`` or ``None`` (the column scaling of
    :func:`hbgear.engine.metric.arclength_sizes`).
    """

    hb: Any
    free_slot: Any
    linearization: Linearization
    sizes: Any = None

    def matvec(self, v):
        """``J diag(sizes) v``."""
        return _product(self.hb, self.free_slot, self.linearization, v if self.sizes is None else v * self.sizes)

    def precondition(self, v):
        """``(Jb diag(sizes))^{-1} v``: the band's solve."""
        out = _precondition(self.hb, self.linearization.band, v)
        return out if self.sizes is None else out / self.sizes

    def scaled(self, sizes) -> KrylovJacobian:
        """``J diag(sizes)``: the same products on scaled directions."""
        return replace(self, sizes=sizes if self.sizes is None else self.sizes * sizes)

    def dense(self):
        """The matrix (``size`` products; the SVD fallback of a failed tangent, the Python corrector)."""
        return jax.vmap(self.matvec, in_axes=1, out_axes=1)(jnp.eye(self.hb.size))

    def bordered_factor(self, column, row) -> KrylovFactor:
        """The :class:`KrylovFactor` of ``[[J, column], [row]]``: its preconditioner bordered
        by the same column and row (``Jb^{-1} column`` and the Schur complement, once)."""
        z_column = self.precondition(column)
        schur = row[-1] - row[:-1] @ z_column
        schur = jnp.where(jnp.abs(schur) > 1e-300, schur, 1.0)  # a degenerate border: the block diagonal
        return KrylovFactor(self, column, row, z_column, schur)


class KrylovFactor(NamedTuple):
    r"""The bordered matrix ``B = [[J, column], [row]]`` of a continuation step, for solves by
    GMRES (:func:`~hbgear.engine.krylov.gmres`) with the bordered band preconditioner
    ``Jb`` (:mod:`hbgear.engine.banded`) on the right,

    .. math:: P = \begin{pmatrix} J_b & c \\ r_z^T & r_p \end{pmatrix},\quad
        P^{-1} \begin{pmatrix} u \\ s \end{pmatrix} = \begin{pmatrix} a - J_b^{-1} c\, y \\ y \end{pmatrix},
        \quad a = J_b^{-1} u,\; y = \frac{s - r_z \cdot a}{r_p - r_z \cdot J_b^{-1} c}

    (block elimination on ``Jb``, which stays regular where ``J`` folds). A pytree."""

    jacobian: KrylovJacobian
    column: Any
    row: Any
    z_column: Any  # Jb^{-1} column
    schur: Any  # row_p - row_z . Jb^{-1} column

    def apply(self, v):
        """``B v``."""
        return jnp.append(self.jacobian.matvec(v[:-1]) + self.column * v[-1], self.row @ v)

    def precondition(self, v):
        """``P^{-1} v``."""
        a = self.jacobian.precondition(v[:-1])
        y = (v[-1] - self.row[:-1] @ a) / self.schur
        return jnp.append(a - self.z_column * y, y)

    def solve(self, b):
        """``B^{-1} b`` to :data:`BORDERED_RTOL` (NaN where GMRES stops above :data:`BORDERED_USABLE_RTOL`)."""
        x, info = gmres(self.apply, b, precondition=self.precondition, rtol=BORDERED_RTOL, restart=RESTART,
                        max_products=BORDERED_MAX_PRODUCTS)
        return jnp.where(info.relative_residual <= BORDERED_USABLE_RTOL, x, jnp.nan)


def krylov_jacobian(hb, z, p, system, prepared) -> KrylovJacobian:
    """``dR/dz`` at ``(z, p)`` as a :class:`KrylovJacobian` (traceable; the continuation's form of
    the structured path)."""
    return KrylovJacobian(hb, system.free_mean_dof, linearization(hb, z, p, system, prepared))
