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
    "convolution_matrix",
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


@lru_cache(maxsize=64)
def _convolution_gather(harmonics: int):
    """Static gather tables for :func:`convolution_matrix`: entry ``(k, l)`` of the real matrix is
    ``sum_j factor[j, k, l] * v[index[j, k, l]]`` with ``v = [Re p_0 .. Re p_2H, Im p_0 .. Im p_2H]``."""
    size = basis_size(harmonics)
    orders = 2 * harmonics + 1
    k = np.zeros(size, dtype=int)
    kind = np.zeros(size, dtype=int)  # 0: constant, 1: cosine, 2: sine
    k[1::2] = k[2::2] = np.arange(1, harmonics + 1)
    kind[1::2], kind[2::2] = 1, 2
    row_k, col_k = np.meshgrid(k, k, indexing="ij")
    row_kind, col_kind = np.meshgrid(kind, kind, indexing="ij")
    adiff, sdiff, ksum = np.abs(row_k - col_k), np.sign(row_k - col_k), row_k + col_k
    re_d, im_d, re_s, im_s = adiff, orders + adiff, ksum, orders + ksum
    index = np.zeros((2, size, size), dtype=int)
    factor = np.zeros((2, size, size))

    def put(mask, i0, f0, i1=None, f1=0.0):
        index[0][mask], factor[0][mask] = np.broadcast_to(i0, mask.shape)[mask], np.broadcast_to(f0, mask.shape)[mask]
        if i1 is not None:
            index[1][mask], factor[1][mask] = np.broadcast_to(i1, mask.shape)[mask], np.broadcast_to(f1, mask.shape)[mask]

    # p_{k-l} = conj p_{l-k}: Im p_{k-l} = sign(k-l) Im p_|k-l|; p_{k+l}
    put((row_kind == 1) & (col_kind == 1), re_d, 1.0, re_s, 1.0)  # cos-cos: Re p_{k-l} + Re p_{k+l}
    put((row_kind == 1) & (col_kind == 2), im_d, sdiff, im_s, -1.0)  # cos-sin: Im p_{k-l} - Im p_{k+l}
    put((row_kind == 2) & (col_kind == 1), im_d, -sdiff, im_s, -1.0)  # sin-cos: -(Im p_{k-l} + Im p_{k+l})
    put((row_kind == 2) & (col_kind == 2), re_d, 1.0, re_s, -1.0)  # sin-sin: Re p_{k-l} - Re p_{k+l}
    put((row_kind == 0) & (col_kind == 1), col_k, 1.0)  # row a_0: Re p_l, -Im p_l
    put((row_kind == 0) & (col_kind == 2), orders + col_k, -1.0)
    put((row_kind == 1) & (col_kind == 0), row_k, 2.0)  # column a_0: 2 Re p_k, -2 Im p_k
    put((row_kind == 2) & (col_kind == 0), orders + row_k, -2.0)
    put((row_kind == 0) & (col_kind == 0), 0, 1.0)  # Re p_0
    return index, factor


def convolution_matrix(p, harmonics: int, xp=np):
    """Real Galerkin matrix of multiplication by a periodic coefficient.

    **Arguments:** `p`: complex coefficients ``p_m``, ``m = 0 .. 2H`` on the base frequency
    (shape ``(..., 2H+1)``, leading axes batched).

    **Returns:** shape ``(..., 2H+1, 2H+1)``, ``T`` with ``coeffs(p x) = T @ coeffs(x)``: with
    ``p_{-m} = conj p_m``, cos-cos ``Re p_{k-l} + Re p_{k+l}``, cos-sin ``Im p_{k-l} - Im p_{k+l}``,
    sin-cos ``-(Im p_{k-l} + Im p_{k+l})``, sin-sin ``Re p_{k-l} - Re p_{k+l}``, row ``a_0``
    ``(Re p_0, Re p_l, -Im p_l)``, column ``a_0`` ``(2 Re p_k, -2 Im p_k)``; two gathers.
    """
    index, factor = _convolution_gather(harmonics)
    p = xp.asarray(p)
    v = xp.concatenate([xp.real(p), xp.imag(p)], axis=-1)
    return v[..., index[0]] * factor[0] + v[..., index[1]] * factor[1]


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
