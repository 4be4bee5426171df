r"""The band preconditioner of the structured path: the harmonic-balance Jacobian's couplings
between harmonics at most :data:`BAND` apart, solved by block elimination.

The linearised force of a periodic system couples harmonic ``l`` of the unknowns into harmonic
``k`` through the Fourier coefficients ``g_{k-l}`` and ``g_{k+l}`` of its periodic coefficients
(``g(t)``: ``K(t) - dQ/dq``, ``C(t) - dQ/dq'``). With ``x = a_0 + sum_l (a_l cos l t + b_l sin l t)``,
``g(t) = sum_m g_m e^{i m t}`` (``g_{-m}`` the conjugate of ``g_m``), the product ``g x``
projected on harmonic ``k`` is, for ``k, l >= 1``,

    a_k += Re(g_{k-l} + g_{k+l}) a_l + (Im g_{k-l} - Im g_{k+l}) b_l
    b_k += -Im(g_{k-l} + g_{k+l}) a_l + (Re g_{k-l} - Re g_{k+l}) b_l

and ``a_k += 2 Re(g_k) a_0``, ``b_k += -2 Im(g_k) a_0``, ``a_0 += Re(g_l) a_l - Im(g_l) b_l``,
``a_0 += Re(g_0) a_0`` for the mean. The Jacobian ``J = conv(K - G_q) + w conv(C - G_v) D_1 +
w^2 M D_1^2`` (``D_1 (a_l, b_l) = (l b_l, -l a_l)``, scaled by ``xs / fs``) restricted to
``|k - l| <= BAND`` is block-tridiagonal in groups of ``BAND`` consecutive harmonics (each
harmonic ``2n`` unknowns: ``a`` of every coordinate, then ``b``; the mean padded with ``n`` unit
unknowns), factored once per linearisation by block elimination (:func:`factor_band`:
``D'_g = D_g - L_g D'_{g-1}^{-1} U_{g-1}``, a scan over the groups) and solved by two scans
(:func:`solve_band`). The free mean slot's column is the unit column, as in ``J``.

Why: the mean Jacobian (one block per harmonic) leaves the mesh stiffness's variation (a square
wave of +-27 % on the reference pair) to GMRES, ~65 products a solve at H = 512; the couplings to
the 4 nearest harmonics on either side take most of it (measured in
``benchmarks/README.md``). The jump terms of the Jacobian are left to GMRES.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["BAND", "BandFactor", "coefficients", "band_blocks", "band_matrix", "factor_band", "solve_band",
           "to_groups", "from_groups"]

#: Harmonics either side of the diagonal kept by the preconditioner (and harmonics per group).
BAND = 4


class BandFactor(NamedTuple):
    """The block elimination of the band (groups ``(G, m, m)``, ``m = 2 n BAND``): `lower`
    ``L_g D'_{g-1}^{-1}``, `inverse` ``D'_g^{-1}``, `upper` ``U_g`` (the coupling to group ``g+1``)."""

    lower: Any
    inverse: Any
    upper: Any


def coefficients(samples, harmonics: int):
    """The complex coefficients ``g_0 .. g_{2H}`` of :func:`band_blocks` from uniform samples
    ``(..., N)`` (zeros past the grid's Nyquist order when ``N <= 4H``)."""
    c = jnp.fft.rfft(samples, axis=-1)[..., : 2 * harmonics + 1] / samples.shape[-1]
    return jnp.concatenate([c, jnp.zeros(c.shape[:-1] + (2 * harmonics + 1 - c.shape[-1],), c.dtype)], axis=-1)


@lru_cache(maxsize=32)
def _layout(harmonics: int, band: int):
    """Static index arrays: for each harmonic ``k`` of the padded range ``0 .. G b - 1`` and offset
    ``d`` in ``-b .. b``, ``l = k + d``, whether ``l`` is a harmonic (``0 <= l <= H``), ``|k - l|`` and
    ``k + l`` (clipped in range)."""
    groups = -(-(harmonics + 1) // band)
    k = np.arange(groups * band)[:, None]
    l = k + np.arange(-band, band + 1)[None, :]
    valid = (l >= 0) & (l <= harmonics) & (k <= harmonics)
    return groups, k, np.clip(l, 0, harmonics), valid


def band_blocks(stiffness, damping, w, mass, scale, harmonics: int, free_slot, band: int = BAND):
    """``E[k, d]``: the ``(2n, 2n)`` block of ``J`` from harmonic ``k + d`` into harmonic ``k``,
    ``(G b, 2b+1, 2n, 2n)`` (zero where ``k + d`` is no harmonic, the identity on padding).

    **Arguments:** `stiffness`, `damping`: complex coefficients ``(n, n, >= 2H+1)`` of
    ``K - G_q`` and ``C - G_v``; `w` the base frequency; `mass` ``(n, n)``; `scale` ``xs / fs``;
    `free_slot` the free mean coordinate or ``None``.
    """
    n = mass.shape[0]
    groups, k, l, valid = _layout(harmonics, band)
    minus, plus = k - l, np.minimum(k + l, 2 * harmonics)

    def convolution(gamma):
        """The ``(2n, 2n)`` blocks of ``conv(g)`` (rows ``a, b`` of harmonic k; columns of harmonic l)."""
        gm = jnp.moveaxis(jnp.moveaxis(gamma[:, :, np.abs(minus)], 0, -1), 0, -1)  # (K, 2b+1, n, n)
        gm = jnp.where((minus < 0)[..., None, None], jnp.conj(gm), gm)
        gp = jnp.moveaxis(jnp.moveaxis(gamma[:, :, plus], 0, -1), 0, -1)
        gp = jnp.where(((k + l) <= 2 * harmonics)[..., None, None], gp, 0.0)
        top = jnp.concatenate([jnp.real(gm + gp), jnp.imag(gm) - jnp.imag(gp)], axis=-1)
        bottom = jnp.concatenate([-jnp.imag(gm + gp), jnp.real(gm) - jnp.real(gp)], axis=-1)
        general = jnp.concatenate([top, bottom], axis=-2)
        # the mean's row (k = 0) and column (l = 0): a_0 has one unknown, b_0 is padding
        zero = jnp.zeros_like(gm)
        column = jnp.concatenate([jnp.concatenate([2 * jnp.real(gm), zero], axis=-1),
                                  jnp.concatenate([-2 * jnp.imag(gm), zero], axis=-1)], axis=-2)
        row = jnp.concatenate([jnp.concatenate([jnp.real(gm), jnp.imag(gm)], axis=-1),  # gm = conj(g_l) here
                               jnp.concatenate([zero, zero], axis=-1)], axis=-2)
        mean = jnp.concatenate([jnp.concatenate([jnp.real(gm), zero], axis=-1),
                                jnp.concatenate([zero, zero], axis=-1)], axis=-2)
        kk, ll = (k + 0 * l)[..., None, None], l[..., None, None]
        return jnp.where((kk == 0) & (ll == 0), mean, jnp.where(kk == 0, row, jnp.where(ll == 0, column, general)))

    eye = jnp.eye(n)
    order = l.astype(float)[..., None, None]
    d1 = jnp.concatenate([jnp.concatenate([0 * eye, eye], axis=-1), jnp.concatenate([-eye, 0 * eye], axis=-1)])
    blocks = convolution(stiffness) + w * order * jnp.einsum("...ij,jk->...ik", convolution(damping), d1)
    blocks = jnp.real(blocks)
    inertia = jnp.kron(jnp.eye(2), mass)
    diagonal = (k == l) & valid
    blocks = blocks - jnp.where(diagonal[..., None, None], (w * order) ** 2 * inertia, 0.0)
    blocks = jnp.where(valid[..., None, None], blocks * scale, 0.0)
    # padding: b_0 and the harmonics past H are unit unknowns
    pad = np.zeros((groups * band, 2 * band + 1, 2 * n, 2 * n))
    pad[0, band, n:, n:] = np.eye(n)
    pad[harmonics + 1 :, band] = np.eye(2 * n)
    blocks = blocks + pad
    if free_slot is not None:  # its column is the unit column (the free mean slot holds a force)
        centre = np.zeros((groups * band, 2 * band + 1, 2 * n), bool)
        centre[:, :, free_slot] = (l == 0) & valid
        blocks = jnp.where(centre[:, :, None, :], 0.0, blocks)
        blocks = blocks.at[0, band, free_slot, free_slot].set(1.0)
    return blocks


def _grouped(blocks, band: int):
    """``(D, L, U)`` ``(G, m, m)``: the band's diagonal groups and their couplings to the previous
    and the next group, from ``E[k, d]``."""
    size = blocks.shape[-1]
    groups = blocks.shape[0] // band
    e = blocks.reshape(groups, band, 2 * band + 1, size, size)
    i = np.arange(band)[:, None]
    j = np.arange(band)[None, :]

    def assemble(shift):  # columns of group g + shift: harmonic (g + shift) b + j, offset d = shift b + j - i
        d = shift * band + j - i
        inside = np.abs(d) <= band
        picked = e[:, i, np.clip(d + band, 0, 2 * band)]  # (G, b, b, size, size)
        picked = jnp.where(inside[None, :, :, None, None], picked, 0.0)
        return jnp.transpose(picked, (0, 1, 3, 2, 4)).reshape(groups, band * size, band * size)

    return assemble(0), assemble(-1), assemble(1)


def factor_band(blocks, band: int = BAND) -> BandFactor:
    """Block elimination of the block-tridiagonal band (:func:`band_blocks`), a scan over groups."""
    diagonal, lower, upper = _grouped(blocks, band)

    def eliminate(carry, dlu):
        inverse_prev, upper_prev = carry
        d, low, up = dlu
        multiplier = low @ inverse_prev
        inverse = jnp.linalg.inv(d - multiplier @ upper_prev)
        return (inverse, up), (multiplier, inverse)

    m = diagonal.shape[-1]
    start = (jnp.zeros((m, m)), jnp.zeros((m, m)))
    _, (multipliers, inverses) = jax.lax.scan(eliminate, start, (diagonal, lower, upper))
    return BandFactor(multipliers, inverses, upper)


def solve_band(factor: BandFactor, rhs):
    """``band^{-1} rhs`` for `rhs` ``(G, m)`` (grouped harmonic-major): forward and back substitution."""
    def forward(previous, pair):
        multiplier, r = pair
        y = r - multiplier @ previous
        return y, y

    _, y = jax.lax.scan(forward, jnp.zeros(rhs.shape[-1]), (factor.lower, rhs))

    def backward(following, triple):
        inverse, up, yy = triple
        x = inverse @ (yy - up @ following)
        return x, x

    _, x = jax.lax.scan(backward, jnp.zeros(rhs.shape[-1]), (factor.inverse, factor.upper, y), reverse=True)
    return x


def to_groups(v, ndof: int, harmonics: int, band: int = BAND):
    """A coordinate-major vector ``(n (2H+1),)`` as grouped harmonic-major ``(G, 2 n b)``: per
    harmonic ``a`` of every coordinate then ``b`` (the mean's ``b`` zero), padded with zeros."""
    groups = -(-(harmonics + 1) // band)
    x = v.reshape(ndof, 2 * harmonics + 1)
    mean = jnp.concatenate([x[:, 0], jnp.zeros(ndof)])[None]
    pairs = jnp.concatenate([x[:, 1::2].T, x[:, 2::2].T], axis=1)  # (H, 2n)
    out = jnp.concatenate([mean, pairs, jnp.zeros((groups * band - harmonics - 1, 2 * ndof))])
    return out.reshape(groups, band * 2 * ndof)


def from_groups(g, ndof: int, harmonics: int):
    """The inverse of :func:`to_groups` (padding dropped)."""
    h = g.reshape(-1, 2 * ndof)
    mean = h[0, :ndof]
    pairs = h[1 : harmonics + 1]
    out = jnp.stack([pairs[:, :ndof].T, pairs[:, ndof:].T], axis=-1).reshape(ndof, 2 * harmonics)
    return jnp.concatenate([mean[:, None], out], axis=1).reshape(-1)


def band_matrix(blocks, ndof: int, harmonics: int, band: int = BAND):
    """The band as a dense matrix in the coordinate-major unknowns (tests)."""
    size = ndof * (2 * harmonics + 1)
    diagonal, lower, upper = _grouped(blocks, band)

    def apply(v):
        g = to_groups(v, ndof, harmonics, band)
        out = jnp.einsum("gij,gj->gi", diagonal, g)
        out = out.at[1:].add(jnp.einsum("gij,gj->gi", lower[1:], g[:-1]))
        out = out.at[:-1].add(jnp.einsum("gij,gj->gi", upper[:-1], g[1:]))
        return from_groups(out, ndof, harmonics)

    return jax.vmap(apply, in_axes=1, out_axes=1)(jnp.eye(size))
