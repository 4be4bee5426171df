r"""Harmonic-balance residual, exact Jacobians and Hill matrices (MODEL.md section 5).

Balanced equation, for a system ``M q'' = Q_lin(s, q, q') + Q_nl(s, q, q')`` (see
:mod:`hbgear.system`) on the base frequency ``w = w_exc / nu``, harmonics ``0..H``::

    R(X) = (M (x) D^2 + K_conv + C_conv (I (x) D)) X - F - P Q_nl(E X, E (I (x) D) X) = 0

- ``X``: real Fourier coefficients, coordinate-major, each ``[a_0, a_1, b_1, ..., a_H, b_H]``
  (:mod:`hbgear.fourier`), scaled by the system's ``displacement_scale``; ``R`` is scaled by
  ``force_scale``.
- ``K_conv``, ``C_conv``, ``F``: Galerkin matrices / vector of the affine periodic part
  ``Q_lin = F(s) - K(s) q - C(s) q'``, from its exact Fourier coefficients (composite
  Gauss--Legendre between the breakpoints, :mod:`hbgear.quadrature`): no sampling error.
- ``E``/``P``: synthesis on / projection from ``N`` uniform samples of the base period (AFT).
- A ``free_mean_dof`` has its mean pinned to zero; its slot in ``X`` holds the constant force
  unknown (e.g. the reaction output torque) instead.

Jacobians come from ``jax.jacfwd``: with respect to ``X`` and to the parameter ``p``.
The Hill eigenproblem of a solution is ``(J + lam D1 + lam^2 D2) v = 0`` with
``D2 = M (x) I`` and ``D1 = 2 M (x) D + dR/d(velocity coefficients)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from . import fourier
from .quadrature import fourier_coefficients, mesh_period_rule

jax.config.update("jax_enable_x64", True)

__all__ = ["HarmonicBalance"]


@dataclass(frozen=True)
class HarmonicBalance:
    """Discretisation settings; methods take the system (a pytree) and the parameter.

    **Arguments:** `ndof`: coordinates; `harmonics`: ``H``; `nu`: 1 (harmonics of the
    excitation) or 2 (adds half orders); `samples`: AFT samples per base period ``N``.
    """

    ndof: int
    harmonics: int
    nu: int = 1
    samples: int = 256

    def __post_init__(self):
        if self.samples < 2 * self.harmonics + 2:
            raise ValueError(f"samples ({self.samples}) must be >= 2 H + 2 = {2 * self.harmonics + 2}")
        if self.samples % self.nu:
            raise ValueError("samples must be a multiple of nu")

    @property
    def block(self) -> int:
        return fourier.basis_size(self.harmonics)

    @property
    def size(self) -> int:
        return self.ndof * self.block

    def base_frequency(self, system, p):
        return system.excitation_frequency(p) / self.nu

    # -- the affine periodic part, exactly ----------------------------------------------------
    def linear_operator(self, system, p):
        """``(L, F)`` in SI: ``L = M D^2 + K_conv + C_conv D`` and the forcing vector ``F``."""
        n, H, nu = self.ndof, self.harmonics, self.nu
        max_mesh_order = -(-2 * H // nu)
        s, w = mesh_period_rule(system.breakpoints(p, jnp), max_mesh_order, jnp)
        zeros = jnp.zeros((n,) + s.shape)
        extra = 0.0
        q0 = system.force(s, zeros, zeros, p, "linear", extra, jnp)
        eye = jnp.eye(n)
        stiff = jnp.stack([q0 - system.force(s, zeros + eye[j][:, None], zeros, p, "linear", extra, jnp) for j in range(n)], axis=1)
        damp = jnp.stack([q0 - system.force(s, zeros, zeros + eye[j][:, None], p, "linear", extra, jnp) for j in range(n)], axis=1)
        coeff = partial(fourier_coefficients, s=s, w=w, max_order=max_mesh_order, xp=jnp)
        base = partial(fourier.mesh_to_base, nu=nu, base_orders=2 * H + 1, xp=jnp)
        k_conv = fourier.convolution_matrix(base(coeff(stiff)), H, jnp)  # (n, n, B, B)
        c_conv = fourier.convolution_matrix(base(coeff(damp)), H, jnp)
        forcing = fourier.coefficients_to_real(base(coeff(q0)), H, jnp)  # (n, B)
        omega = self.base_frequency(system, p)
        d = fourier.derivative_matrix(H, omega, jnp)
        mass = system.mass_matrix(p, jnp)
        op = mass[:, :, None, None] * (d @ d)[None, None] + k_conv + c_conv @ d[None, None]
        big = jnp.transpose(op, (0, 2, 1, 3)).reshape(self.size, self.size)
        return big, forcing.reshape(self.size)

    # -- residual --------------------------------------------------------------------------------
    def _split(self, system, z):
        """Scaled unknowns -> (X in SI, extra force)."""
        x = z * system.displacement_scale
        k = system.free_mean_dof
        if k is None:
            return x, 0.0
        slot = k * self.block
        extra = z[slot] * system.force_scale
        return x.at[slot].set(0.0), extra

    def _residual(self, z, p, system, velocity_shift=None, pinned=True):
        n, H, N, nu = self.ndof, self.harmonics, self.samples, self.nu
        if pinned:
            x, extra = self._split(system, z)
        else:
            x, extra = z * system.displacement_scale, 0.0
        lin, forcing = self.linear_operator(system, p)
        omega = self.base_frequency(system, p)
        d = fourier.derivative_matrix(H, omega, jnp)
        xc = x.reshape(n, self.block)
        vc = xc @ d.T
        if velocity_shift is not None:
            vc = vc + velocity_shift.reshape(n, self.block) * system.displacement_scale
            # the damping part of the linear operator acts on the shifted velocity too
        r = lin @ x - forcing
        if velocity_shift is not None:
            r = r + self._damping_operator(system, p) @ (velocity_shift * system.displacement_scale)
        k = system.free_mean_dof
        if k is not None and pinned:
            r = r.at[k * self.block].add(extra)
        if not system.is_linear:
            q = fourier.synthesize(xc, H, N, jnp)
            qd = fourier.synthesize(vc, H, N, jnp)
            s = jnp.mod(jnp.arange(N) * nu / N, 1.0)
            fnl = system.force(s, q, qd, p, "nonlinear", extra, jnp)
            r = r - fourier.project(fnl, H, jnp).reshape(self.size)
        return r / system.force_scale

    def _damping_operator(self, system, p):
        """``C_conv`` (SI), the Galerkin matrix of the affine velocity terms."""
        n, H, nu = self.ndof, self.harmonics, self.nu
        max_mesh_order = -(-2 * H // nu)
        s, w = mesh_period_rule(system.breakpoints(p, jnp), max_mesh_order, jnp)
        zeros = jnp.zeros((n,) + s.shape)
        q0 = system.force(s, zeros, zeros, p, "linear", 0.0, jnp)
        eye = jnp.eye(n)
        damp = jnp.stack([q0 - system.force(s, zeros, zeros + eye[j][:, None], p, "linear", 0.0, jnp) for j in range(n)], axis=1)
        coeff = fourier_coefficients(damp, s, w, max_mesh_order, jnp)
        c_conv = fourier.convolution_matrix(fourier.mesh_to_base(coeff, nu, 2 * H + 1, jnp), H, jnp)
        return jnp.transpose(c_conv, (0, 2, 1, 3)).reshape(self.size, self.size)

    @partial(jax.jit, static_argnums=0)
    def residual(self, z, p, system):
        """Scaled residual ``R(z; p)``, shape ``(size,)``."""
        return self._residual(z, p, system)

    @partial(jax.jit, static_argnums=0)
    def residual_and_jacobians(self, z, p, system):
        """``(R, dR/dz, dR/dp)``."""
        r = self._residual(z, p, system)
        jz, jp = jax.jacfwd(self._residual, argnums=(0, 1))(z, p, system)
        return r, jz, jp

    @partial(jax.jit, static_argnums=0)
    def hill_matrices(self, z, p, system):
        """``(J, D1, D2)`` of the Hill eigenproblem at a solution (mean unpinned), scaled."""
        x, _ = self._split(system, z)
        z_free = x / system.displacement_scale
        zero = jnp.zeros_like(z)
        jz, jv = jax.jacfwd(
            lambda zz, vv: self._residual(zz, p, system, velocity_shift=vv, pinned=False), argnums=(0, 1)
        )(z_free, zero)
        omega = self.base_frequency(system, p)
        d = fourier.derivative_matrix(self.harmonics, omega, jnp)
        mass = system.mass_matrix(p, jnp) * system.displacement_scale / system.force_scale
        eye = jnp.eye(self.block)
        d2 = jnp.kron(mass, eye)
        d1 = jv + 2 * jnp.kron(mass, d)
        return jz, d1, d2
