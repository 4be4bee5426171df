r"""Quadrature over one mesh period for functions that are smooth between known breakpoints.

The periodic coefficients of the gear pair (``k(t)``, ``c(t)``, nominal friction, their
products with the STE) jump at pair entry, pair exit and the pitch crossings. A uniform grid
would alias those jumps (error ``O(1/N)``); composite Gauss--Legendre between the breakpoints is
exact to rounding for piecewise polynomials and spectrally accurate for smooth pieces, so the
Fourier coefficients

    f_r = \int_0^1 f(s) e^{-2 pi i r s} ds,   r = 0 .. r_max

come out exact "to quadrature precision". Sub-intervals are graded geometrically towards each
breakpoint so that steep but smooth laws (arctan with a small ``V0`` at the pitch point) are
resolved too.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Any, NamedTuple

import numpy as np

__all__ = ["mesh_period_rule", "fourier_coefficients", "LatticeRule", "lattice_rule", "lattice_coefficients",
           "lattice_synthesis"]

_GL_ORDER = 8
_GRADE_LEVELS = 14

#: Complex entries per work array of :func:`lattice_synthesis` (16 MB). The read-outs of 128
#: points at H = 512 (18032 nodes, 24 progressions): 0.43-0.44 s in blocks of 2**20 entries,
#: 0.86 s (1.8 s on a process's first call: fresh memory) in blocks of 2**22, 0.47 s in 2**18,
#: 0.62 s in 2**16; the same values to the bit.
SYNTHESIS_BLOCK = 2**20


@lru_cache(maxsize=None)
def _gauss_legendre() -> tuple[np.ndarray, np.ndarray]:
    """The ``_GL_ORDER``-point Gauss-Legendre nodes and weights on [-1, 1] (computed once, read-only)."""
    x, wx = np.polynomial.legendre.leggauss(_GL_ORDER)
    x.flags.writeable = wx.flags.writeable = False
    return x, wx


@lru_cache(maxsize=256)
def _unit_layout(sub_intervals: int, grade_levels: int) -> np.ndarray:
    """Static sub-interval edges in [0, 1]: uniform, graded towards both ends (cached, read-only)."""
    uniform = np.linspace(0.0, 1.0, sub_intervals + 1)
    first = uniform[1]
    graded = first * 10.0 ** (-0.5 * np.arange(1, grade_levels + 1))
    edges = np.unique(np.concatenate([uniform, graded, 1.0 - graded]))
    edges.flags.writeable = False
    return edges


def mesh_period_rule(breakpoints, max_order: int, xp=np, same_nodes: bool = False):
    """Nodes ``s_i`` in [0, 1) and weights ``w_i`` (summing to 1) for one mesh period.

    **Arguments:**

    - `breakpoints`: 1-D array of phases in [0, 1] where the integrand may jump (may be
      traced; duplicates and out-of-range values are harmless: they are clipped).
    - `max_order`: highest harmonic ``r`` to be integrated accurately (sets the density).
    - `same_nodes`: with numpy too, the layout of the traced rule (every interval the same number
      of sub-intervals), so that a quantity computed once in numpy and once in a compiled
      function is the same number to rounding even where its integrand is not smooth between
      the breakpoints (the two layouts then differ beyond rounding).

    **Returns:** ``(s, w)``, shapes ``(n,)``; ``n`` depends only on the number of breakpoints
    and `max_order`, so the rule is jit-friendly.
    """
    a, b, sub = _intervals(breakpoints, max_order, xp)
    if xp is np and not same_nodes:  # concrete breakpoints: sub-intervals in proportion to each interval's width
        return _proportional_rule(np.asarray(a), np.asarray(b), sub)
    unit = _unit_layout(sub, _GRADE_LEVELS)
    x, wx = _gauss_legendre()
    lo, hi = unit[:-1], unit[1:]
    unit_nodes = (0.5 * (lo + hi)[:, None] + 0.5 * (hi - lo)[:, None] * x[None]).ravel()
    unit_weights = (0.5 * (hi - lo)[:, None] * wx[None]).ravel()
    width = b - a
    s = (a[:, None] + width[:, None] * xp.asarray(unit_nodes)[None]).ravel()
    w = (width[:, None] * xp.asarray(unit_weights)[None]).ravel()
    return s, w


def _intervals(breakpoints, max_order: int, xp=np):
    """``(a, b, sub)``: the intervals between the sorted breakpoints and the uniform
    sub-intervals per unit width (phase span ``2 pi r h <= 3`` per sub-interval with 8-point
    Gauss--Legendre: error ~1e-11)."""
    bp = xp.sort(xp.clip(xp.asarray(breakpoints, dtype=float), 0.0, 1.0))
    edges = xp.concatenate([xp.zeros(1), bp, xp.ones(1)])
    return edges[:-1], edges[1:], max(4, int(np.ceil(2.1 * max(max_order, 1))))


def _proportional_rule(a: np.ndarray, b: np.ndarray, sub: int):
    """The rule of :func:`mesh_period_rule` with ``ceil(sub * width)`` sub-intervals per interval."""
    pieces = _proportional_pieces(a, b, sub)
    return np.concatenate([p[0] for p in pieces]), np.concatenate([p[1] for p in pieces])


def _proportional_pieces(a: np.ndarray, b: np.ndarray, sub: int):
    """Per interval of positive width: ``(nodes, weights, lo, width, m)``, ``m`` its uniform
    sub-intervals (:func:`_unit_layout`, the first and last one graded towards the ends)."""
    x, wx = _gauss_legendre()
    pieces = []
    for lo, hi in zip(a, b):
        width = hi - lo
        if width <= 0.0:
            continue
        m = max(2, int(np.ceil(sub * width)))
        unit = _unit_layout(m, _GRADE_LEVELS)
        u0, u1 = unit[:-1], unit[1:]
        nodes = (lo + width * (0.5 * (u0 + u1)[:, None] + 0.5 * (u1 - u0)[:, None] * x[None])).ravel()
        pieces.append((nodes, (width * 0.5 * (u1 - u0)[:, None] * wx[None]).ravel(), float(lo), float(width), m))
    return pieces


def fourier_coefficients(values, s, w, max_order: int, xp=np):
    """Complex Fourier coefficients ``f_r = sum_i w_i f(s_i) exp(-2 pi i r s_i)``.

    **Arguments:** `values`: samples at the nodes, shape ``(..., n)``; `s`, `w`: the rule.

    **Returns:** shape ``(..., max_order + 1)``; ``f(s) = f_0 + 2 Re sum_r f_r e^{2 pi i r s}``.
    """
    order = xp.arange(max_order + 1)
    phase = 2 * np.pi * order[:, None] * s[None, :]
    cos = xp.cos(phase) * w[None, :]
    sin = xp.sin(phase) * w[None, :]
    return values @ cos.T - 1j * (values @ sin.T)


# ============================================================================ lattice rule


class LatticeRule(NamedTuple):
    r"""The rule of :func:`mesh_period_rule` (concrete breakpoints) with its structure, for
    Fourier sums at high orders without an ``(orders x nodes)`` kernel (:func:`lattice_rule`).

    The nodes of the uniform sub-intervals of an interval, one Gauss point at a time, are
    arithmetic progressions ``s = start_p + l step_p`` (``l < L_p``): a sum
    ``sum_l y_l exp(-2 pi i r s_l)`` over one is a chirp transform (:func:`_chirp`, two FFTs).
    The other nodes (the sub-intervals graded towards the breakpoints, ``D`` of them, a number
    that does not grow with the order) are summed directly, with their kernel
    ``exp(-2 pi i r s_d) w_d`` held here.

    **Fields:** `nodes`, `weights` ``(n,)`` (those of :func:`mesh_period_rule`); `start`,
    `step` ``(P,)``; `index` ``(P, L)`` node of each progression entry (padding: node 0);
    `mask` ``(P, L)`` 1 on entries, 0 on padding; `pre` ``(P, L)``, `kernel` ``(P, F)``,
    `post` ``(P, R+1)`` the chirp transform's factors (:func:`_chirp_factors`; the weights in
    `pre`, the shift ``exp(-2 pi i r start_p)`` in `post`); `direct` ``(D,)`` the other
    nodes; `direct_kernel` ``(D, R+1)``.
    """

    nodes: Any
    weights: Any
    start: Any
    step: Any
    index: Any
    mask: Any
    pre: Any
    kernel: Any
    post: Any
    direct: Any
    direct_kernel: Any


def lattice_rule(breakpoints, max_order: int, coefficients: bool = True) -> LatticeRule:
    """The :class:`LatticeRule` of ``mesh_period_rule(breakpoints, max_order)`` (numpy).

    The progressions are read off the construction of :func:`_proportional_pieces` (15 graded
    cells, ``m - 2`` uniform ones, 15 graded cells per interval) and checked against the nodes.
    `coefficients`: build the factors of :func:`lattice_coefficients` (``False``: ``None``,
    a rule for :func:`lattice_synthesis` only, without the ``D x (R+1)`` direct kernel).
    """
    a, b, sub = _intervals(np.asarray(breakpoints), max_order)
    x, _ = _gauss_legendre()
    order = len(x)
    first = _GRADE_LEVELS + 1  # cells [0, 1/m] graded into _GRADE_LEVELS + 1 pieces
    rows, starts, steps, direct, nodes, weights = [], [], [], [], [], []
    offset = 0
    for piece_nodes, piece_weights, lo, width, m in _proportional_pieces(np.asarray(a), np.asarray(b), sub):
        cells = len(piece_nodes) // order
        uniform = np.arange(first, first + m - 2)
        h = width / m
        for g in range(order if m > 2 else 0):
            rows.append(offset + order * uniform + g)
            starts.append(lo + h * (1.0 + 0.5 * (1.0 + x[g])))
            steps.append(h)
        graded = np.setdiff1d(np.arange(cells), uniform)
        direct.append(offset + (order * graded[:, None] + np.arange(order)[None]).ravel())
        nodes.append(piece_nodes)
        weights.append(piece_weights)
        offset += len(piece_nodes)
    nodes, weights, direct = np.concatenate(nodes), np.concatenate(weights), np.concatenate(direct)
    length = max((len(r) for r in rows), default=0)
    index = np.zeros((len(rows), length), dtype=int)
    mask = np.zeros((len(rows), length))
    for p, r in enumerate(rows):
        index[p, : len(r)], mask[p, : len(r)] = r, 1.0
    start, step = np.asarray(starts, dtype=float), np.asarray(steps, dtype=float)
    lattice = start[:, None] + step[:, None] * np.arange(length)[None]
    if np.max(np.abs(nodes[index] - lattice) * mask, initial=0.0) > 1e-13:
        raise AssertionError("the mesh-period rule's uniform sub-intervals are not the progressions expected")
    if not coefficients:
        return LatticeRule(nodes, weights, start, step, index, mask, None, None, None, direct, None)
    pre, kernel, post = _chirp_factors(2 * np.pi * step, length, max_order + 1)
    pre = pre * mask * weights[index]
    post = post * _powers(-start, max_order + 1)
    direct_kernel = np.ascontiguousarray(_powers(-nodes[direct], max_order + 1))
    direct_kernel *= weights[direct][:, None]
    return LatticeRule(nodes, weights, start, step, index, mask, pre, kernel, post, direct, direct_kernel)


def lattice_coefficients(values, rule: LatticeRule, xp=np):
    """``f_r = sum_i w_i f(s_i) exp(-2 pi i r s_i)``, ``r = 0 .. R`` (:func:`fourier_coefficients`
    on the rule's nodes, ``R`` that of the rule's kernel): chirp transforms over the progressions,
    the direct kernel over the rest; ``O(n log n)`` per row instead of ``O(n R)``.

    **Arguments:** `values` ``(..., n)`` real at the rule's nodes. **Returns:** ``(..., R+1)``.
    """
    orders = rule.direct_kernel.shape[-1]
    f = _apply_chirp(values[..., rule.index], rule.pre, rule.kernel, rule.post, xp)  # (..., P, R+1)
    direct = values[..., rule.direct]  # one 2-D product (a stacked one is not a single BLAS call)
    direct = (direct.reshape(-1, direct.shape[-1]) @ rule.direct_kernel).reshape(values.shape[:-1] + (orders,))
    return xp.sum(f, axis=-2) + direct


def lattice_synthesis(coefficients, rule: LatticeRule, shift: float = 0.0, scale: float = 1.0,
                      block: int = SYNTHESIS_BLOCK):
    """``Re sum_k c_k exp(2 pi i k t_i)`` at ``t_i = shift + scale s_i`` for every node of the rule
    (numpy; the transpose of :func:`lattice_coefficients`, with the direct nodes' basis built here).

    **Arguments:** `coefficients` ``(..., K+1)`` complex; `block`: complex entries per work
    array (rows are done in chunks). **Returns:** ``(..., n)``.
    """
    c = np.asarray(coefficients)
    flat = c.reshape(-1, c.shape[-1])
    twist = _powers(shift + scale * rule.start, c.shape[-1])  # (P, K+1)
    basis = _powers(shift + scale * rule.nodes[rule.direct], c.shape[-1]).T  # (K+1, D)
    keep = rule.mask > 0
    out = np.empty((flat.shape[0], rule.nodes.shape[0]))
    rows = max(1, block // max(1, twist.size))
    for i in range(0, flat.shape[0], rows):
        part = flat[i : i + rows]
        values = _chirp(part[:, None, :] * twist[None], -2 * np.pi * scale * rule.step, rule.index.shape[1], np)
        out[i : i + rows, rule.index[keep]] = values[:, keep].real
        out[i : i + rows, rule.direct] = (part @ basis).real
    return out.reshape(c.shape[:-1] + (rule.nodes.shape[0],))


def _powers(t, count: int) -> np.ndarray:
    """``exp(2 pi i k t)`` for ``k < count``, shape ``t.shape + (count,)`` (numpy): products of
    ``~sqrt(count)`` low and high powers, each an exponential (``2 sqrt(count)`` exponentials
    per ``t`` instead of ``count``; rounding as of two exponentials)."""
    t = np.asarray(t, dtype=float)[..., None]
    low = int(np.ceil(np.sqrt(count)))
    lows = np.exp(2j * np.pi * t * np.arange(low))
    highs = np.exp(2j * np.pi * t * (low * np.arange(-(-count // low))))
    return (highs[..., :, None] * lows[..., None, :]).reshape(t.shape[:-1] + (-1,))[..., :count]


def _chirp(x, theta, out_len: int, xp=np):
    """``y_m = sum_{l < L} x_l exp(-i theta l m)``, ``m < out_len``, along the last axis;
    `theta` ``x.shape[-2:-1]`` (one per progression). See :func:`_chirp_factors`."""
    return _apply_chirp(x, *_chirp_factors(theta, x.shape[-1], out_len, xp), xp)


def _chirp_factors(theta, length: int, out_len: int, xp=np):
    """``(pre, kernel, post)`` of the chirp transform ``y_m = sum_{l < L} x_l exp(-i theta l m)``
    (Bluestein: ``l m = (l^2 + m^2 - (m - l)^2) / 2`` makes it the convolution
    ``y = post * ((x pre) * b)``, ``b_k = exp(i theta k^2 / 2)``, done by FFTs of a length
    ``F >= L + out_len - 1``): ``pre = exp(-i theta l^2/2)`` ``(P, L)``, `kernel` the FFT of
    ``b`` ``(P, F)``, ``post = exp(-i theta m^2/2)`` ``(P, out_len)``."""
    import scipy.fft  # here, not at import: the curves of few harmonics never need it (0.1 s of every run)

    size = scipy.fft.next_fast_len(max(1, length + out_len - 1))
    theta = xp.asarray(theta)[:, None]
    l, m = np.arange(length), np.arange(out_len)
    lag = np.concatenate([np.arange(out_len), np.zeros(max(0, size - out_len - length + 1)),
                          -np.arange(length - 1, 0, -1)])[:size]
    used = np.ones(size)
    used[out_len : size - length + 1] = 0.0
    kernel = xp.fft.fft(xp.exp(0.5j * theta * lag**2) * used, axis=-1)
    return xp.exp(-0.5j * theta * l**2), kernel, xp.exp(-0.5j * theta * m**2)


def _apply_chirp(x, pre, kernel, post, xp=np):
    """The chirp transform of `x` ``(..., P, L)`` with its factors (:func:`_chirp_factors`)."""
    if x.shape[-1] == 0:
        return xp.zeros(x.shape[:-1] + (post.shape[-1],), dtype=complex)
    product = xp.fft.fft(x * pre, n=kernel.shape[-1], axis=-1) * kernel
    return xp.fft.ifft(product, axis=-1)[..., : post.shape[-1]] * post
