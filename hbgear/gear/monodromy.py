r"""Exact and variational monodromy of the gear pair's periodic steady states (MODEL.md section 6).

- **Exact monodromy for linear models** (:func:`monodromy_linear`, :func:`monodromy_ltv_a`).
  For LTV formulation A (and LTI) the coefficients are piecewise constant in the mesh phase
  (``k(t)`` is a rectangular pulse, friction is an excitation), so the monodromy matrix over
  one mesh period is the exact product of matrix exponentials of the paper's Eq. 20. For
  LTV formulation B the coefficients are piecewise smooth (``xi_j(t)`` is linear in ``t``);
  fourth-order Magnus steps between the breakpoints are used. Both are batched over speeds.
- **Variational equations** (:func:`monodromy_variational`): ``solve_ivp`` over one base
  period, segment by segment between the breakpoints, with ``Q_q``, ``Q_qd`` from ``jax.jacfwd``
  of :meth:`~hbgear.gear.model.GearPairModel.generalized_force` along the periodic solution.

Limitation: with the Coulomb law (``sgn``) the linearisation ignores the jumps of ``mu`` at
the instantaneous pitch-point crossings of NLTV models (no saltation matrices); smooth laws
(arctan) are treated exactly.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..engine.floquet import TRIVIAL_TOL, hill_multipliers

__all__ = [
    "expm_batched",
    "floquet_multipliers",
    "monodromy_linear",
    "monodromy_ltv_a",
    "monodromy_variational",
    "multipliers_linear",
    "solution_multipliers",
]

_SQRT3 = np.sqrt(3.0)
_GAUSS2 = (0.5 - _SQRT3 / 6.0, 0.5 + _SQRT3 / 6.0)


def _drop_trivial(multipliers: np.ndarray, boundary: str, tol: float = TRIVIAL_TOL) -> np.ndarray:
    """Remove up to two multipliers within `tol` of 1 for the reaction boundary (last axis)."""
    m = np.asarray(multipliers)
    if boundary != "reaction":
        return m
    flat = m.reshape(-1, m.shape[-1])
    out = []
    for row in flat:
        dist = np.abs(row - 1.0)
        order = np.argsort(dist)
        drop = [i for i in order[:2] if dist[i] < tol]
        out.append(np.delete(row, drop))
    width = min(len(r) for r in out)
    # keep a rectangular array: rows that kept more (a trivial pair not found) keep the largest
    out = [r[np.argsort(-np.abs(r))][:width] for r in out]
    return np.asarray(out).reshape(m.shape[:-1] + (width,))


# ============================================================================ batched expm

# Pade(13) coefficients and the theta of Higham (2005), "The scaling and squaring method for
# the matrix exponential revisited".
_PADE13 = np.array(
    [
        64764752532480000.0, 32382376266240000.0, 7771770303897600.0, 1187353796428800.0,
        129060195264000.0, 10559470521600.0, 670442572800.0, 33522128640.0, 1323241920.0,
        40840800.0, 960960.0, 16380.0, 182.0, 1.0,
    ]
)
_THETA13 = 5.371920351148152


def expm_batched(a: np.ndarray) -> np.ndarray:
    """``exp(A)`` for a stack of small matrices, shape ``(..., m, m)``, fully vectorised.

    Scaling and squaring with the [13/13] Pade approximant (Higham 2005): the same accuracy as
    :func:`scipy.linalg.expm`, but batched in NumPy (about 100x faster for thousands of 4x4
    matrices, which is what a stability map needs).
    """
    a = np.asarray(a, dtype=float)
    shape = a.shape
    m = shape[-1]
    a = a.reshape(-1, m, m)
    norm = np.max(np.sum(np.abs(a), axis=-2), axis=-1)  # 1-norm
    with np.errstate(divide="ignore"):
        squarings = np.maximum(0, np.ceil(np.log2(np.maximum(norm, 1e-300) / _THETA13))).astype(int)
    a = a / (2.0 ** squarings)[:, None, None]
    b = _PADE13
    eye = np.broadcast_to(np.eye(m), a.shape)
    a2 = a @ a
    a4 = a2 @ a2
    a6 = a4 @ a2
    u = a @ (a6 @ (b[13] * a6 + b[11] * a4 + b[9] * a2) + b[7] * a6 + b[5] * a4 + b[3] * a2 + b[1] * eye)
    v = a6 @ (b[12] * a6 + b[10] * a4 + b[8] * a2) + b[6] * a6 + b[4] * a4 + b[2] * a2 + b[0] * eye
    r = np.linalg.solve(v - u, v + u)
    for k in range(int(squarings.max(initial=0))):
        more = squarings > k
        r = np.where(more[:, None, None], r @ r, r)
    return r.reshape(shape)


# ============================================================================ linear models


def _linear_coefficients(model, s: np.ndarray, omega: float):
    """``K(s)``, ``C(s)`` of the homogeneous part ``M q'' = -K q - C q'``, shapes ``(len(s), n, n)``.

    From differences of the (affine) generalised force, so every term the model has (mesh,
    formulation-B friction, soft spring) is included.
    """
    n = model.ndof
    s = np.asarray(s, dtype=float)
    zeros = np.zeros((n,) + s.shape)
    q0 = np.asarray(model.generalized_force(s, zeros, zeros, omega, "all", 0.0, 0.0, np))
    stiff = np.empty((s.size, n, n))
    damp = np.empty((s.size, n, n))
    for j in range(n):
        unit = zeros.copy()
        unit[j] = 1.0
        stiff[:, :, j] = (q0 - np.asarray(model.generalized_force(s, unit, zeros, omega, "all", 0.0, 0.0, np))).T
        damp[:, :, j] = (q0 - np.asarray(model.generalized_force(s, zeros, unit, omega, "all", 0.0, 0.0, np))).T
    return stiff, damp


def _reference_frequency(model) -> float:
    """``w_n = sqrt(k_mean / m_e)`` [rad/s], the velocity scale of the balanced state."""
    return float(np.sqrt(float(model.k_mean_N_per_m) / float(model.mass_equivalent_kg)))


def _state_matrices(model, s: np.ndarray, omega: float) -> np.ndarray:
    """Balanced first-order ``A(s)``: ``y = (q, q'/w_n)``, ``y' = A y``; shape ``(len(s), 2n, 2n)``.

    Displacements and scaled velocities are of the same size, so the eigenvalues of the
    monodromy matrix come out to ~1e-14 instead of ~1e-10 (they are similarity invariant).
    """
    n = model.ndof
    wn = _reference_frequency(model)
    stiff, damp = _linear_coefficients(model, s, omega)
    minv = np.linalg.inv(np.asarray(model.mass_matrix(np), dtype=float))
    a = np.zeros((len(s), 2 * n, 2 * n))
    a[:, :n, n:] = wn * np.eye(n)
    a[:, n:, :n] = -(minv @ stiff) / wn
    a[:, n:, n:] = -minv @ damp
    return a


def _is_piecewise_constant(model) -> bool:
    """LTI, or LTV formulation A: homogeneous coefficients constant between breakpoints."""
    if not model.is_linear:
        return False
    return model.coupling == "LTI" or (model.coupling == "LTV" and model.formulation == "A")


def _magnus_terms(model, omega: float, substeps: int):
    """Per step ``(P, Q)`` with the Magnus exponent ``Omega = Tm P + Tm^2 Q`` over a mesh period.

    Fourth-order Magnus with two Gauss points on `substeps` equal sub-steps of every segment
    between the breakpoints; exact (``Q = 0``, one step) for piecewise-constant coefficients.
    """
    edges = np.unique(np.concatenate([[0.0], np.asarray(model.phase_breakpoints(), float), [1.0]]))
    edges = edges[(edges >= 0.0) & (edges <= 1.0)]
    left, right = edges[:-1], edges[1:]
    keep = right - left > 1e-14
    left, right = left[keep], right[keep]
    frac = np.arange(substeps) / substeps
    h = np.repeat((right - left) / substeps, substeps)
    left = (left[:, None] + (right - left)[:, None] * frac[None]).ravel()
    a1 = _state_matrices(model, left + _GAUSS2[0] * h, omega)
    a2 = _state_matrices(model, left + _GAUSS2[1] * h, omega)
    p = 0.5 * h[:, None, None] * (a1 + a2)
    q = (_SQRT3 / 12.0) * (h**2)[:, None, None] * (a2 @ a1 - a1 @ a2)
    return p, q


def monodromy_linear(model, omegas, *, substeps: int | None = None, balanced: bool = False) -> np.ndarray:
    """Monodromy matrices over one mesh period of a linear model, batched over speeds.

    **Arguments:**

    - `model`: a :class:`~hbgear.gear.model.GearPairModel` with ``model.is_linear`` (LTI, or LTV
      with teeth that never separate).
    - `omegas`: pinion speeds ``Omega_p`` [rad/s], scalar or 1-D.
    - `substeps`: Magnus sub-steps per segment; default 1 for piecewise-constant models
      (exact), 16 otherwise (formulation B: relative error ~1e-10).
    - `balanced`: return the matrix for ``y = (q, q'/w_n)`` instead (same eigenvalues, better
      conditioned; ``w_n = sqrt(k_mean/m_e)``).

    **Returns:** ``Phi`` with ``x(Tm) = Phi x(0)``, ``x = (q, q')`` in SI; shape
    ``(len(omegas), 2n, 2n)`` (or ``(2n, 2n)`` for a scalar speed).

    **Raises:** `ValueError` for a non-linear model (use :func:`monodromy_variational`).
    """
    if not model.is_linear:
        raise ValueError(
            f"monodromy_linear needs a linear model (LTI/LTV without backlash), got coupling="
            f"{model.coupling!r}, contact={model.contact!r}; use monodromy_variational or Hill"
        )
    scalar = np.ndim(omegas) == 0
    omegas = np.atleast_1d(np.asarray(omegas, dtype=float))
    if substeps is None:
        substeps = 1 if _is_piecewise_constant(model) else 16
    period = 2.0 * np.pi / (float(model.teeth_pinion) * omegas)  # mesh period Tm [s]
    p, q = _magnus_terms(model, float(omegas[0]), substeps)
    shared = True
    if omegas.size > 1 and not _is_piecewise_constant(model):
        p_last, q_last = _magnus_terms(model, float(omegas[-1]), substeps)
        scale = max(np.max(np.abs(p)), 1e-300)
        shared = np.allclose(p, p_last, rtol=1e-12, atol=1e-14 * scale) and np.allclose(
            q, q_last, rtol=1e-12, atol=1e-14 * scale**2
        )
    if shared:
        exponent = period[:, None, None, None] * p[None] + (period**2)[:, None, None, None] * q[None]
    else:  # speed-dependent coefficients (e.g. a friction law of the sliding speed)
        terms = [_magnus_terms(model, float(w), substeps) for w in omegas]
        p = np.stack([t[0] for t in terms])
        q = np.stack([t[1] for t in terms])
        exponent = period[:, None, None, None] * p + (period**2)[:, None, None, None] * q
    steps = expm_batched(exponent)  # (n_omega, n_steps, 2n, 2n)
    phi = steps[:, 0]
    for k in range(1, steps.shape[1]):
        phi = steps[:, k] @ phi
    if not balanced:
        n = model.ndof
        scale = np.concatenate([np.ones(n), np.full(n, _reference_frequency(model))])
        phi = scale[:, None] * phi / scale[None, :]
    return phi[0] if scalar else phi


def monodromy_ltv_a(model, omega) -> np.ndarray:
    """Exact monodromy matrix over one mesh period for LTV formulation A (paper Eq. 20).

    ``Phi = prod_j exp(A_j (s_{j+1} - s_j) Tm)`` over the segments between the breakpoints
    (pair entry, pair exit, pitch crossing), where ``A_j`` is the constant state matrix of
    segment ``j``. `omega` [rad/s] scalar -> ``(2n, 2n)``; 1-D -> ``(len, 2n, 2n)``.

    **Raises:** `ValueError` unless the model is LTV (or LTI), formulation A, without backlash.
    """
    if not _is_piecewise_constant(model):
        raise ValueError(
            "monodromy_ltv_a needs an LTV formulation-A (or LTI) model without backlash, got "
            f"coupling={model.coupling!r}, formulation={model.formulation!r}, contact={model.contact!r}"
        )
    return monodromy_linear(model, omega, substeps=1)


def multipliers_linear(model, omegas, *, substeps: int | None = None, drop_trivial: bool = True) -> np.ndarray:
    """Floquet multipliers (per mesh period) of a linear model; shape ``(len(omegas), 2n')``.

    ``2n' = 2n`` minus the trivial pair of the reaction boundary when `drop_trivial`.
    """
    scalar = np.ndim(omegas) == 0
    phi = monodromy_linear(model, np.atleast_1d(omegas), substeps=substeps, balanced=True)
    mult = np.linalg.eigvals(phi)
    if drop_trivial:
        mult = _drop_trivial(mult, model.boundary)
    return mult[0] if scalar else mult


# ============================================================================ variational


_VARIATIONAL_RHS = None


def _variational_rhs():
    """The jitted right-hand side of the variational equations at one instant (built once; the
    model is a pytree): ``Phi' = scale A Phi``, ``A = [[0, I], [M^-1 dQ/dq, M^-1 dQ/dq']]``,
    i.e. ``[Phi_v; M^-1 (dQ/dq Phi_q + dQ/dq' Phi_v)]`` with ``Phi = [Phi_q; Phi_v]``, flattened.
    One compiled call per evaluation (the ODE solver calls it ~1000 times per monodromy, ~30000
    at 200 rpm), whose changing inputs come packed in one vector ``y = [s, q, q', Phi]`` (one
    transfer instead of four: ~35 instead of ~55 us a call)."""
    global _VARIATIONAL_RHS
    if _VARIATIONAL_RHS is None:
        import jax
        import jax.numpy as jnp

        jax.config.update("jax_enable_x64", True)

        def rhs(model, omega, u_static, reaction, minv, scale, y):
            n = minv.shape[0]
            s, q, qd, phi = y[0], y[1 : 1 + n], y[1 + n : 1 + 2 * n], y[1 + 2 * n :]

            def force(q, qd):
                return model.generalized_force(s, q, qd, omega, "all", u_static, reaction, jnp)

            dq, dqd = jax.jacfwd(force, argnums=(0, 1))(q, qd)
            phi = phi.reshape(2 * n, 2 * n)
            velocity_rows = minv @ (dq @ phi[:n] + dqd @ phi[n:])
            return (scale * jnp.concatenate([phi[n:], velocity_rows])).ravel()

        _VARIATIONAL_RHS = jax.jit(rhs)
    return _VARIATIONAL_RHS


def _state_synthesis(solution):
    """``tau -> (q, q')`` of a periodic solution at the base-period fraction ``tau`` (numpy),
    from one complex matrix of its coefficients: ``[q; q'] = Re S e(tau)``, ``e_k = exp(2 pi i k tau)``,
    ``k = 0 .. H``, the powers as the outer product of ``~sqrt(H)`` low and ``~sqrt(H)`` high
    ones (``2 sqrt(H)`` exponentials per instant instead of ``2H`` sines and cosines).

    In numpy, not in the compiled right-hand side: a reduction over the harmonics there makes
    XLA hand the program to its worker thread, which costs more than the whole evaluation."""
    c = np.asarray(solution.coefficients, dtype=float)  # (ndof, 2H+1): a0, a1, b1, ...
    harmonics, n = solution.harmonics, c.shape[0]
    k = np.arange(harmonics + 1)
    position = np.concatenate([c[:, :1], c[:, 1::2] - 1j * c[:, 2::2]], axis=1)  # q = Re sum c_k e^{i k t}
    synthesis = np.concatenate([position, 1j * solution.base_frequency * k * position])
    low = int(np.ceil(np.sqrt(harmonics + 1)))
    low_orders = 2j * np.pi * np.arange(low)
    high_orders = 2j * np.pi * low * np.arange(-(-(harmonics + 1) // low))

    def state(tau):
        powers = (np.exp(high_orders * tau)[:, None] * np.exp(low_orders * tau)[None]).ravel()[: harmonics + 1]
        x = (synthesis @ powers).real
        return x[:n], x[n:]

    return state


def monodromy_variational(
    model,
    solution_or_state_fn: Any,
    omega: float,
    nu: int = 1,
    *,
    rtol: float = 1e-10,
    atol: float = 1e-12,
) -> np.ndarray:
    """Monodromy matrix over one base period ``nu Tm`` from the variational equations.

    ``Phi' = A(t) Phi``, ``A = [[0, I], [M^-1 dQ/dq, M^-1 dQ/dq']]`` along the periodic solution,
    integrated by :func:`scipy.integrate.solve_ivp` (DOP853) in the normalised time
    ``tau = t / (nu Tm)``, restarting at every breakpoint of every mesh period so that the
    integrator never steps across a jump of ``k(t)`` or of the nominal sliding direction.

    **Arguments:**

    - `model`: any :class:`~hbgear.gear.model.GearPairModel` (formulation B, NLTV, backlash, ...).
    - `solution_or_state_fn`: a :class:`~hbgear.gear.solve.PeriodicSolution` (its ``state_at``,
      ``u_static_m`` and ``reaction_force_N`` are used; its ``nu`` overrides `nu`) or a callable
      ``base_fraction -> (q, q')`` with arrays of shape ``(ndof,)`` or ``(ndof, 1)`` [m, m/s].
    - `omega`: pinion speed ``Omega_p`` [rad/s]; `nu`: base period in mesh periods.

    **Returns:** ``Phi``, shape ``(2n, 2n)``, ``x(nu Tm) = Phi x(0)``.
    """
    import jax
    from scipy.integrate import solve_ivp

    n = model.ndof
    if hasattr(solution_or_state_fn, "state_at"):
        solution = solution_or_state_fn
        nu = int(solution.nu)
        u_static = float(solution.u_static_m)
        reaction = float(solution.reaction_force_N)
        state = _state_synthesis(solution)
    else:
        state_fn = solution_or_state_fn
        u_static = float(model.static_windup(omega))
        reaction = 0.0

        def state(tau):
            q, qd = state_fn(np.array([tau]))
            return np.asarray(q, float).reshape(n), np.asarray(qd, float).reshape(n)

    variational_rhs = _variational_rhs()
    minv = np.linalg.inv(np.asarray(model.mass_matrix(np), dtype=float))
    base_period = nu * 2.0 * np.pi / (float(model.teeth_pinion) * float(omega))
    bp = np.unique(np.concatenate([[0.0], np.asarray(model.phase_breakpoints(), float), [1.0]]))
    edges = np.unique(np.concatenate([(j + bp) / nu for j in range(nu)]))
    # the arguments that stay the same over the ~1000 calls go to the device once (a Python float
    # or numpy argument is converted at every call: most of the cost of a call before)
    device_model, *constants = jax.device_put((model, float(omega), u_static, reaction, minv, base_period))

    def derivative(tau, s, phi):
        q, qd = state(tau)
        return np.asarray(variational_rhs(device_model, *constants, np.concatenate([[s], q, qd, phi])))

    def s_lo_of(start):
        return (start * nu) % 1.0

    phi = np.eye(2 * n)
    for a, b in zip(edges[:-1], edges[1:]):
        if b - a < 1e-14:
            continue
        # the mesh phases of this segment, kept strictly inside it (one-sided limits at jumps)
        s_lo = (a * nu) % 1.0
        s_hi = s_lo + (b - a) * nu
        lo, hi = s_lo + 1e-12, min(s_hi, 1.0) - 1e-12

        def rhs(tau, y, lo=lo, hi=hi, start=a):
            s = float(np.clip(s_lo_of(start) + (tau - start) * nu, lo, hi))
            return derivative(tau, s, y)

        sol = solve_ivp(rhs, (a, b), phi.ravel(), method="DOP853", rtol=rtol, atol=atol)
        if not sol.success:
            raise RuntimeError(f"variational equations failed on [{a:.6g}, {b:.6g}]: {sol.message}")
        phi = sol.y[:, -1].reshape(2 * n, 2 * n)
    return phi


# ============================================================================ dispatch


def solution_multipliers(solution) -> np.ndarray:
    """Floquet multipliers of a :class:`~hbgear.gear.solve.PeriodicSolution` over its base period,
    trivial ones dropped, sorted by decreasing modulus.

    Hill's method on the harmonic-balance Jacobian where the discretisation is dense; on the
    structured path (many harmonics, :attr:`hbgear.engine.hb.HarmonicBalance.structured`) the
    variational equations (:func:`monodromy_variational`): Hill's matrices would be
    ``(size x size)`` and its eigenproblem ``O(size^3)``, while the variational equations cost
    the same at any ``H`` (the solution enters only through its state along the period).
    """
    from ..engine.hb import HarmonicBalance
    from .system import GearSystem

    model = solution.model
    hb = HarmonicBalance(model.ndof, solution.harmonics, solution.nu, solution.samples)
    if not hb.structured:
        return hill_multipliers(hb, solution.z, solution.omega_pinion, GearSystem(model))
    phi = monodromy_variational(model, solution, solution.omega_pinion)
    multipliers = _drop_trivial(np.linalg.eigvals(phi), model.boundary)
    return multipliers[np.argsort(-np.abs(multipliers), kind="stable")]


def floquet_multipliers(
    model,
    omega: float,
    *,
    solution=None,
    harmonics: int = 24,
    nu: int = 1,
    samples: int | None = None,
    method: str = "auto",
) -> np.ndarray:
    """Floquet multipliers of the steady state at `omega` [rad/s].

    `method`: ``"auto"`` (exact monodromy for linear models, else Hill), ``"monodromy"``,
    ``"hill"`` or ``"variational"``. For non-linear models a
    :class:`~hbgear.gear.solve.PeriodicSolution` may be given, else one is solved for.
    Multipliers from Hill and the variational equations are over the base period ``nu Tm``.
    """
    if method == "auto":
        method = "monodromy" if model.is_linear else "hill"
    if method == "monodromy":
        return multipliers_linear(model, float(omega))
    from ..engine.hb import HarmonicBalance
    from .solve import solve_periodic
    from .system import GearSystem

    if solution is None:
        solution = solve_periodic(model, omega, harmonics=harmonics, nu=nu, samples=samples)
    if method == "variational":
        phi = monodromy_variational(model, solution, omega)
        return _drop_trivial(np.linalg.eigvals(phi), model.boundary)
    if method != "hill":
        raise ValueError(f"method must be 'auto', 'monodromy', 'hill' or 'variational', got {method!r}")
    hb = HarmonicBalance(model.ndof, solution.harmonics, solution.nu, solution.samples)
    return hill_multipliers(hb, solution.z, float(omega), GearSystem(model))


