r"""Real Fourier basis for harmonic balance on the base frequency ``w = w_m / nu``.

A coordinate is ``x(tau) = a_0 + sum_{k=1..H} a_k cos(k tau) + b_k sin(k tau)``, ``tau = w t``,
stored as the vector ``[a_0, a_1, b_1, ..., a_H, b_H]`` (length ``2H+1``); several coordinates
are stacked coordinate-major.

A periodic coefficient ``p(tau) = sum_m p_m e^{i m tau}`` (``p_{-m} = conj p_m``) acting on ``x``
is the real convolution matrix of :func:`convolution_matrix`, built from the exact complex
coefficients ``p_0 .. p_{2H}``: the Galerkin projection of ``p x`` onto the basis, with no
sampling error. Nonlinear terms use alternating frequency-time on ``N`` uniform samples of the
base period (:func:`synthesize`, :func:`project`, real FFTs).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

__all__ = [
    "basis_size",
    "derivative_matrix",
    "differentiate",
    "convolution_matrix",
    "convolution_gather",
    "coefficients_to_real",
    "synthesize",
    "project",
    "mesh_to_base",
    "harmonic_amplitudes",
]


def basis_size(harmonics: int) -> int:
    """``2H + 1``."""
    return 2 * harmonics + 1


def derivative_matrix(harmonics: int, omega, xp=np):
    """``D`` with ``(x')`` coefficients ``= D @ x`` coefficients: ``a_k' = k w b_k``, ``b_k' = -k w a_k``."""
    k = np.arange(1, harmonics + 1, dtype=float)
    d = np.zeros((basis_size(harmonics), basis_size(harmonics)))
    d[2 * k.astype(int) - 1, 2 * k.astype(int)] = k
    d[2 * k.astype(int), 2 * k.astype(int) - 1] = -k
    return omega * xp.asarray(d)


def differentiate(x, harmonics: int, omega, xp=np):
    """``D @ x`` along the last axis without the matrix (:func:`derivative_matrix`):
    ``a_k' = k w b_k``, ``b_k' = -k w a_k``, ``a_0' = 0``; `x` shape ``(..., 2H+1)``."""
    x = xp.asarray(x)
    k = omega * xp.asarray(np.arange(1, harmonics + 1, dtype=float))
    pairs = xp.stack([k * x[..., 2::2], -k * x[..., 1::2]], axis=-1).reshape(x.shape[:-1] + (2 * harmonics,))
    return xp.concatenate([0.0 * x[..., :1], pairs], axis=-1)


def convolution_matrix(p, harmonics: int, xp=np):
    """Real Galerkin matrix of multiplication by a periodic coefficient.

    **Arguments:** `p`: complex coefficients ``p_m``, ``m = 0 .. 2H`` on the base frequency
    (shape ``(..., 2H+1)``, leading axes batched; ``Im p_0`` is ignored).

    **Returns:** shape ``(..., 2H+1, 2H+1)``, ``T`` with ``coeffs(p x) = T @ coeffs(x)``: with
    ``p_{-m} = conj p_m``, the complex Toeplitz ``P_kl = p_{k-l}`` and Hankel ``Q_kl = p_{k+l}``
    (``k, l = 0..H``), cos-cos ``Re(P + Q)``, cos-sin ``Im(P - Q)``, sin-cos ``-Im(P + Q)``,
    sin-sin ``Re(P - Q)``; the row of ``a_0`` halved (``Re p_0``, ``Re p_l``, ``-Im p_l``).
    """
    p = xp.asarray(p)[..., : 2 * harmonics + 1]
    n = harmonics + 1
    re, im = xp.real(p), xp.imag(p)
    zero = 0.0 * im[..., :1]
    # Toeplitz from [p_H .. p_1, p_0, conj p_1 .. conj p_H] with a stride one shorter than its
    # period (each row starts one entry earlier); Hankel from p_0 .. p_2H with a stride one longer
    rev = lambda a: a[..., n - 1 : 0 : -1]  # noqa: E731
    t_re = _toeplitz(xp.concatenate([rev(re), re[..., :1], re[..., 1:n]], axis=-1), n, xp)
    t_im = _toeplitz(xp.concatenate([rev(im), zero, -im[..., 1:n]], axis=-1), n, xp)
    h_re, h_im = _hankel(re, n, xp), _hankel(im, n, xp)
    blocks = xp.stack([xp.stack([t_re + h_re, t_im - h_im], axis=-1),
                       xp.stack([-t_im - h_im, t_re - h_re], axis=-1)], axis=-3)  # (..., k, cos|sin, l, cos|sin)
    full = xp.reshape(blocks, p.shape[:-1] + (2 * n, 2 * n))  # [a_0, b_0, a_1, b_1, ...]: drop b_0
    full = xp.concatenate([0.5 * full[..., :1, :], full[..., 2:, :]], axis=-2)
    return xp.concatenate([full[..., :1], full[..., 2:]], axis=-1)


@lru_cache(maxsize=16)
def convolution_gather(harmonics: int, derivative: bool = False):
    """``(index, factor)``, each ``(2, B, B)`` (numpy, read-only): :func:`convolution_matrix` as a
    gather, ``T[b, d] = factor[0, b, d] v[index[0, b, d]] + factor[1, b, d] v[index[1, b, d]]``
    with ``v = [Re p_0 .. Re p_2H, Im p_0 .. Im p_2H]``; with `derivative`, ``T D_1``
    (:func:`derivative_matrix` at unit frequency).

    Every entry of ``T`` is a sum of at most two coefficients (one Toeplitz, one Hankel term), so
    two gathers make it in one pass, where the Toeplitz and Hankel strides of
    :func:`convolution_matrix` take several (on XLA's CPU backend the difference is about a
    third of the assembly of a multi-port Jacobian). Derived from :func:`convolution_matrix`
    itself, applied to the unit coefficients.
    """
    b = basis_size(harmonics)
    units = np.concatenate([np.eye(b), 1j * np.eye(b)]).astype(complex)  # (2B, B): v's unit vectors
    terms = convolution_matrix(units, harmonics)  # (2B, B, B): T of each unit
    if derivative:
        terms = terms @ derivative_matrix(harmonics, 1.0)
    nonzero = terms != 0.0
    if nonzero.sum(axis=0).max() > 2:
        raise AssertionError("a convolution-matrix entry with more than two terms")
    # the (at most two) units of each entry: the nonzero ones first, a zero factor pads
    index = np.argsort(~nonzero, axis=0, kind="stable")[:2]
    factor = np.take_along_axis(terms, index, axis=0)
    index, factor = index.astype(np.int32), np.ascontiguousarray(factor)
    index.flags.writeable = factor.flags.writeable = False
    return index, factor


def _toeplitz(w, n: int, xp):
    """``T_kl = w[n - 1 - k + l]``, ``k, l < n``, from ``w`` of length ``2n - 1``."""
    flat = xp.tile(w, (1,) * (w.ndim - 1) + (n + 1,))
    rows = flat[..., n - 1 : n - 1 + n * (2 * n - 2)]
    return xp.reshape(rows, w.shape[:-1] + (n, 2 * n - 2))[..., :n]


def _hankel(u, n: int, xp):
    """``Q_kl = u[k + l]``, ``k, l < n``, from ``u`` of length ``2n - 1``."""
    flat = xp.tile(u, (1,) * (u.ndim - 1) + (n + 1,))
    return xp.reshape(flat[..., : 2 * n * n], u.shape[:-1] + (n, 2 * n))[..., :n]


def coefficients_to_real(f, harmonics: int, xp=np):
    """Complex coefficients ``f_0 .. f_H`` (shape ``(..., >= H+1)``) -> real vector ``(..., 2H+1)``."""
    f = xp.asarray(f)[..., : harmonics + 1]
    cos = 2 * xp.real(f[..., 1:])
    sin = -2 * xp.imag(f[..., 1:])
    pairs = xp.reshape(xp.stack([cos, sin], axis=-1), f.shape[:-1] + (2 * harmonics,))
    return xp.concatenate([xp.real(f[..., :1]), pairs], axis=-1)


def mesh_to_base(f_mesh, nu: int, base_orders: int, xp=np):
    """Mesh-order coefficients ``f_r`` -> base-harmonic coefficients ``f_m`` (``m = nu r``).

    **Arguments:** `f_mesh`: shape ``(..., R+1)``; `base_orders`: number of base harmonics
    wanted (``m = 0 .. base_orders-1``), needs ``R >= (base_orders-1)//nu``.
    """
    f_mesh = xp.asarray(f_mesh)
    if nu == 1:
        return f_mesh[..., :base_orders]
    m = np.arange(base_orders)
    take = np.where(m % nu == 0, m // nu, 0)
    return xp.where(xp.asarray(m % nu == 0), f_mesh[..., take], 0.0 * f_mesh[..., take])


def synthesize(x, harmonics: int, samples: int, xp=np):
    """Samples of ``x(tau_j)``, ``tau_j = 2 pi j / N``; `x` shape ``(..., 2H+1)`` -> ``(..., N)``."""
    x = xp.asarray(x)
    a0 = x[..., :1]
    a = x[..., 1::2]
    b = x[..., 2::2]
    spectrum = xp.concatenate([a0 + 0j, 0.5 * (a - 1j * b)], axis=-1) * samples
    pad = samples // 2 + 1 - (harmonics + 1)
    spectrum = xp.concatenate([spectrum, xp.zeros(spectrum.shape[:-1] + (pad,), dtype=spectrum.dtype)], axis=-1)
    return xp.fft.irfft(spectrum, n=samples, axis=-1)


def project(y, harmonics: int, xp=np):
    """Real coefficients of uniform samples `y` (shape ``(..., N)``) -> ``(..., 2H+1)``."""
    samples = y.shape[-1]
    spectrum = xp.fft.rfft(y, axis=-1)[..., : harmonics + 1] / samples
    return coefficients_to_real(spectrum, harmonics, xp)


def harmonic_amplitudes(x, harmonics: int, xp=np):
    """``(mean, amplitude_k, phase_k)`` with ``x = mean + sum A_k cos(k tau + phi_k)``."""
    x = xp.asarray(x)
    a, b = x[..., 1::2], x[..., 2::2]
    return x[..., 0], xp.sqrt(a**2 + b**2), xp.arctan2(-b, a)
