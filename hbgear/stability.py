r"""Floquet stability of periodic steady states (MODEL.md section 6).

A periodic solution ``q*(t)`` of ``M q'' = Q(s, q, q')`` is stable iff every Floquet
multiplier of the linearised equations

    M y'' = Q_q(t) y + Q_qd(t) y',      Q_q = dQ/dq,  Q_qd = dQ/dq'  along q*(t)

has modulus below one (trivial rigid-body multipliers excepted). Three ways to get them:

- **Exact monodromy for linear models** (:func:`monodromy_linear`, :func:`monodromy_ltv_a`).
  For LTV formulation A (and LTI) the coefficients are piecewise constant in the mesh phase
  (``k(t)`` is a rectangular pulse, friction is an excitation), so the monodromy matrix over
  one mesh period is the exact product of matrix exponentials of the paper's Eq. 20. For
  LTV formulation B the coefficients are piecewise smooth (``xi_j(t)`` is linear in ``t``);
  fourth-order Magnus steps between the breakpoints are used. Both are batched over speeds.
- **Variational equations** (:func:`monodromy_variational`): ``solve_ivp`` over one base
  period, segment by segment between the breakpoints, with ``Q_q``, ``Q_qd`` from ``jax.jacfwd``
  of :meth:`~hbgear.model.GearPairModel.generalized_force` along the periodic solution.
- **Hill's method** (:func:`hill_multipliers`, :func:`hill_multipliers_batch`) on the
  harmonic-balance Jacobian: of the quadratic eigenproblem ``(J + lam D1 + lam^2 D2) v = 0``,
  whose ``2 n (2H+1)`` eigenvalues come in families of copies ``lam + i k w`` (one multiplier
  each), the ``2n`` members whose eigenvectors are most concentrated on the central harmonics
  are kept (Lazarus & Thomas 2010); multipliers ``exp(lam T)``, ``T = 2 pi / w``. By default
  only those central eigenpairs are computed (refined from a low-harmonic sub-problem, batched
  over points, see :mod:`hbgear.hill`); ``method="dense"`` takes all eigenpairs of the companion
  linearisation instead, with the same result.

Trivial multipliers: with the ``"reaction"`` boundary the coordinate ``u`` has no restoring
force, so the linearisation has the exponent 0 twice (a Jordan block: ``u = const``,
``u = t``); those (at most two, within :data:`TRIVIAL_TOL` of 0) are dropped. The ``"spring"``
boundary's soft mode is a real, lightly damped mode (multiplier just inside the unit circle)
and is kept.

Limitation: with the Coulomb law (``sgn``) the linearisation ignores the jumps of ``mu`` at
the instantaneous pitch-point crossings of NLTV models (no saltation matrices), both in the
variational equations and in Hill's method; smooth laws (arctan) are treated exactly.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

__all__ = [
    "TRIVIAL_TOL",
    "StabilityInfo",
    "classify",
    "floquet_multipliers",
    "hill_exponents",
    "hill_exponents_batch",
    "hill_multipliers",
    "hill_multipliers_batch",
    "is_stable",
    "max_abs_multiplier",
    "most_negative_real",
    "model_at_contact_ratio",
    "monodromy_linear",
    "monodromy_ltv_a",
    "monodromy_variational",
    "multipliers_linear",
    "period_doubling",
    "stability_map",
    "stability_map_ltv_a",
    "stability_row",
]

#: Multipliers within this distance of 1 (exponents within ``TRIVIAL_TOL/(2 pi)`` of 0, in
#: units of the base frequency) count as the trivial rigid-body ones of the reaction boundary.
TRIVIAL_TOL = 1e-5

_SQRT3 = np.sqrt(3.0)
_GAUSS2 = (0.5 - _SQRT3 / 6.0, 0.5 + _SQRT3 / 6.0)


# ============================================================================ classification


class StabilityInfo(NamedTuple):
    """Summary of a set of Floquet multipliers.

    **Fields:** `max_abs` (largest modulus); `stable` (see :func:`is_stable`); `kind`: ``"stable"``,
    ``"period-doubling"`` (a real multiplier below -1: continue the ``nu = 2`` branch),
    ``"fold"`` (a real multiplier above +1) or ``"secondary-hopf"`` (a complex pair outside).
    """

    max_abs: float
    stable: bool
    kind: str


def max_abs_multiplier(multipliers) -> float:
    """``max |mu_i|`` (``nan`` for an empty or non-finite set)."""
    m = np.asarray(multipliers)
    if m.size == 0 or not np.all(np.isfinite(m)):
        return float("nan")
    return float(np.max(np.abs(m)))


def is_stable(multipliers, tol: float = 1e-9) -> bool:
    """``True`` iff every multiplier has ``|mu| <= 1 + tol`` (the trivial ones already dropped).

    The small tolerance keeps a neutrally stable mode (exactly on the unit circle up to
    rounding, e.g. an undamped model) from being reported unstable.
    """
    value = max_abs_multiplier(multipliers)
    return bool(np.isfinite(value) and value <= 1.0 + tol)


def period_doubling(multipliers, tol: float = 1e-9) -> bool:
    """``True`` iff a real multiplier lies below ``-1 - tol`` (it left through -1).

    The caller should then continue the sub-harmonic branch (``nu = 2``, MODEL.md section 6).
    "Real" means ``|Im mu| <= 1e-6 |mu|`` (a complex pair that collided on the negative real axis
    becomes real there).
    """
    return bool(most_negative_real(multipliers) < -1.0 - tol)


def most_negative_real(multipliers) -> float:
    """The most negative real multiplier (``nan`` if none); "real" as in :func:`period_doubling`."""
    m = np.asarray(multipliers)
    negative = m.real[(np.abs(m.imag) <= 1e-6 * np.maximum(np.abs(m), 1.0)) & (m.real < 0)]
    return float(np.min(negative)) if negative.size else float("nan")


def classify(multipliers, tol: float = 1e-9) -> StabilityInfo:
    """Stable, or how the dominant multiplier left the unit circle."""
    m = np.asarray(multipliers)
    value = max_abs_multiplier(m)
    if is_stable(m, tol):
        return StabilityInfo(value, True, "stable")
    if not np.isfinite(value):
        return StabilityInfo(value, False, "unknown")
    lead = m[np.argmax(np.abs(m))]
    if abs(lead.imag) <= 1e-6 * abs(lead):
        return StabilityInfo(value, False, "period-doubling" if lead.real < 0 else "fold")
    return StabilityInfo(value, False, "secondary-hopf")


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

    - `model`: a :class:`~hbgear.model.GearPairModel` with ``model.is_linear`` (LTI, or LTV
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
    One compiled call per evaluation (the ODE solver calls it ~1000 times per monodromy)."""
    global _VARIATIONAL_RHS
    if _VARIATIONAL_RHS is None:
        import jax
        import jax.numpy as jnp

        jax.config.update("jax_enable_x64", True)

        def rhs(model, s, q, qd, omega, u_static, reaction, minv, scale, phi):
            def force(q, qd):
                return model.generalized_force(s, q, qd, omega, "all", u_static, reaction, jnp)

            dq, dqd = jax.jacfwd(force, argnums=(0, 1))(q, qd)
            n = q.shape[0]
            phi = phi.reshape(2 * n, 2 * n)
            velocity_rows = minv @ (dq @ phi[:n] + dqd @ phi[n:])
            return (scale * jnp.concatenate([phi[n:], velocity_rows])).ravel()

        _VARIATIONAL_RHS = jax.jit(rhs)
    return _VARIATIONAL_RHS


def _state_synthesis(solution):
    """``tau -> (q, q')`` of a periodic solution at the base-period fraction ``tau`` (numpy),
    from one matrix of its coefficients: ``[q; q'] = S [1, cos(2 pi k tau), sin(2 pi k tau)]``.

    In numpy, not in the compiled right-hand side: a reduction over the harmonics there makes
    XLA hand the program to its worker thread, which costs more than the whole evaluation."""
    c = np.asarray(solution.coefficients, dtype=float)  # (ndof, 2H+1): a0, a1, b1, ...
    harmonics, n = solution.harmonics, c.shape[0]
    k = np.arange(1, harmonics + 1)
    a, b = c[:, 1::2], c[:, 2::2]
    synthesis = np.concatenate([
        np.concatenate([c[:, :1], a, b], axis=1),
        np.concatenate([np.zeros((n, 1)), solution.base_frequency * b * k, -solution.base_frequency * a * k], axis=1),
    ])
    orders = 2.0 * np.pi * k

    def state(tau):
        angle = orders * tau
        x = synthesis @ np.concatenate([[1.0], np.cos(angle), np.sin(angle)])
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

    - `model`: any :class:`~hbgear.model.GearPairModel` (formulation B, NLTV, backlash, ...).
    - `solution_or_state_fn`: a :class:`~hbgear.solve.PeriodicSolution` (its ``state_at``,
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
        return np.asarray(variational_rhs(device_model, s, q, qd, *constants, phi))

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


# ============================================================================ Hill's method


def _zero_tol(system, drop_trivial: bool):
    """Exponent tolerance (``mu = lam / w``) of the trivial pair, or ``None`` when none is dropped."""
    if drop_trivial and getattr(system, "free_mean_dof", None) is not None:
        return TRIVIAL_TOL / (2.0 * np.pi)
    return None


def hill_exponents_batch(hb, zs, ps, system, *, drop_trivial: bool = True, copy_tol: float = 1e-6,
                         method: str = "auto"):
    """:func:`hill_exponents` at many points ``(zs[i], ps[i])`` of one problem, as a list.

    Small problems get their Hill matrices from one jitted, vmapped call per chunk of points;
    the refinement runs stacked over all points (:func:`hbgear.hill.refined_central_batch`).
    On the Duffing benchmark (H = 7) this is several times cheaper per point than one call per
    point.
    """
    from .hill import central_exponents, hill_quadratic

    ps = np.atleast_1d(np.asarray(ps, dtype=float))
    if ps.size == 0:
        return []
    a0, a1, a2, w = hill_quadratic(hb, zs, ps, system)
    mus = central_exponents(a0, a1, a2, hb.ndof, hb.harmonics, zero_tol=_zero_tol(system, drop_trivial),
                            copy_tol=copy_tol, method=method)
    out = []
    for mu, wk in zip(mus, w):
        mult = np.exp(2.0 * np.pi * mu)
        order = np.argsort(-np.abs(mult), kind="stable")
        out.append((mu[order] * wk, mult[order]))
    return out


def hill_exponents(hb, z, p, system, *, drop_trivial: bool = True, copy_tol: float = 1e-6, method: str = "auto"):
    """The ``2n`` Floquet exponents picked from the Hill spectrum, and their multipliers.

    **Returns:** ``(lam, mult)``: exponents [1/s] and multipliers ``exp(lam T)`` over the base
    period ``T = 2 pi / w`` (``w = w_mesh / nu``), sorted by decreasing ``|mult|``.

    Of every family of copies ``lam + i k w`` of the quadratic eigenproblem
    ``(J + mu w D1 + mu^2 w^2 D2) v = 0`` (``lam = mu w``) the member whose eigenvector is most
    concentrated on the central harmonics is kept (:mod:`hbgear.hill`). `method`: ``"dense"``
    (all eigenpairs of the companion linearisation) or ``"refined"`` = ``"auto"`` (the central
    eigenpairs only, by inverse iteration seeded from the low harmonics; the dense way where
    that is not confident): the same exponents either way (to ~1e-13 in the tests).
    With the reaction boundary the (at most two) exponents within ``TRIVIAL_TOL`` of 0 are
    dropped.
    """
    return hill_exponents_batch(hb, np.asarray(z)[None], [p], system, drop_trivial=drop_trivial,
                                copy_tol=copy_tol, method=method)[0]


def hill_multipliers(hb, z, p, system, **kwargs) -> np.ndarray:
    """Floquet multipliers of a harmonic-balance solution by Hill's method.

    **Arguments:** `hb`: the :class:`~hbgear.hb.HarmonicBalance` used to solve; `z`: its scaled
    unknowns (``PeriodicSolution.z``); `p`: the parameter (pinion speed [rad/s] for a
    ``GearSystem`` in speed); `system`: the system. Keywords go to :func:`hill_exponents`.

    **Returns:** the ``2n`` multipliers (less the trivial pair of the reaction boundary) over
    the base period ``2 pi nu / w_mesh``, sorted by decreasing modulus.
    """
    return hill_exponents(hb, z, p, system, **kwargs)[1]


def hill_multipliers_batch(hb, zs, ps, system, **kwargs) -> list[np.ndarray]:
    """:func:`hill_multipliers` at many points of one problem (see :func:`hill_exponents_batch`)."""
    return [mult for _, mult in hill_exponents_batch(hb, zs, ps, system, **kwargs)]


# ============================================================================ dispatch


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
    :class:`~hbgear.solve.PeriodicSolution` may be given, else one is solved for.
    Multipliers from Hill and the variational equations are over the base period ``nu Tm``.
    """
    if method == "auto":
        method = "monodromy" if model.is_linear else "hill"
    if method == "monodromy":
        return multipliers_linear(model, float(omega))
    from .hb import HarmonicBalance
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


# ============================================================================ maps


def model_at_contact_ratio(cfg, contact_ratio: float):
    """``build_model(cfg, contact_ratio=...)``: ``k_max``, ``k_min`` held, ``k_mean`` follows (MODEL.md section 2)."""
    from .build import build_model

    return build_model(cfg, contact_ratio=float(contact_ratio))


def _models(cfg_or_models, contact_ratios):
    if isinstance(cfg_or_models, Sequence) and not isinstance(cfg_or_models, str):
        return list(cfg_or_models), [float(m.contact_ratio) for m in cfg_or_models]
    from .build import build_model

    if contact_ratios is None:
        return [build_model(cfg_or_models)], None
    return [model_at_contact_ratio(cfg_or_models, g) for g in contact_ratios], list(contact_ratios)


def stability_map_ltv_a(cfg_or_models, speeds_rpm, contact_ratios=None) -> np.ndarray:
    """``max |multiplier|`` over speed x contact ratio for LTV formulation A, exactly and fast.

    **Arguments:** `cfg_or_models`: a ``RunConfig`` (one model per contact ratio is built with
    :func:`model_at_contact_ratio`, ``k_max``/``k_min`` held) or a sequence of models;
    `speeds_rpm`: 1-D pinion speeds [rpm]; `contact_ratios`: 1-D (with a config).

    **Returns:** array ``(len(contact_ratios), len(speeds_rpm))`` of the largest multiplier
    modulus per mesh period (trivial rigid-body pair of the reaction boundary excluded).

    All matrix exponentials of one contact ratio (segments x speeds) are one batched Pade
    evaluation (:func:`expm_batched`); a 100 x 50 map takes well under a second.

    **Raises:** `ValueError` if a model is not LTV-A/LTI (use :func:`stability_map`).
    """
    models, _ = _models(cfg_or_models, contact_ratios)
    omegas = np.asarray(speeds_rpm, dtype=float) * (2.0 * np.pi / 60.0)
    out = np.empty((len(models), omegas.size))
    for i, model in enumerate(models):
        if not _is_piecewise_constant(model):
            raise ValueError("stability_map_ltv_a needs LTV formulation-A (or LTI) models; use stability_map")
        out[i] = np.max(np.abs(multipliers_linear(model, omegas, substeps=1)), axis=-1)
    return out


@dataclass(frozen=True)
class _HBSettings:
    harmonics: int = 24
    nu: int = 1
    samples: int | None = None


def _row_for_model(model, omegas: np.ndarray, settings: _HBSettings):
    """max |multiplier| at each speed for one model: batched monodromy if linear, else HB + Hill."""
    if model.is_linear:
        return np.max(np.abs(multipliers_linear(model, omegas)), axis=-1)
    from .errors import ConvergenceError
    from .hb import HarmonicBalance
    from .solve import solve_periodic
    from .system import GearSystem

    out = np.full(omegas.size, np.nan)
    z = None
    solved, zs = [], []
    for k, omega in enumerate(omegas):
        try:
            sol = solve_periodic(
                model, float(omega), harmonics=settings.harmonics, nu=settings.nu, samples=settings.samples, z0=z
            )
        except ConvergenceError:
            z = None
            continue
        z = sol.z
        solved.append(k)
        zs.append(np.asarray(sol.z))
        hb = HarmonicBalance(model.ndof, sol.harmonics, sol.nu, sol.samples)
    if solved:
        # one batched Hill call for the row (all points share hb: same H, nu, N)
        mults = hill_multipliers_batch(hb, np.stack(zs), omegas[solved], GearSystem(model))
        # per mesh period, comparable with the linear maps
        out[solved] = [max_abs_multiplier(m) ** (1.0 / hb.nu) for m in mults]
    return out


def _settings(cfg) -> _HBSettings:
    solver = getattr(cfg, "solver", None)
    if solver is None:
        return _HBSettings()
    harmonics = solver.harmonics if solver.harmonics is not None else 24
    return _HBSettings(harmonics=int(harmonics), nu=int(solver.subharmonic), samples=int(solver.time_samples))


def stability_row(cfg, contact_ratio: float, speeds_rpm) -> np.ndarray:
    """One row of the map: ``max |multiplier|`` over `speeds_rpm` at one contact ratio.

    The unit of work of ``hbgear stability-map`` (one task per contact ratio when distributed).
    Linear models use the batched exact monodromy; others harmonic balance + Hill (``nan``
    where harmonic balance does not converge).
    """
    model = model_at_contact_ratio(cfg, contact_ratio)
    omegas = np.asarray(speeds_rpm, dtype=float) * (2.0 * np.pi / 60.0)
    return _row_for_model(model, omegas, _settings(cfg))


def stability_map(cfg_or_models, speeds_rpm, contact_ratios=None) -> np.ndarray:
    """``max |multiplier|`` over contact ratio x speed for any model (see :func:`stability_row`).

    **Returns:** array ``(len(contact_ratios), len(speeds_rpm))``.
    """
    models, _ = _models(cfg_or_models, contact_ratios)
    omegas = np.asarray(speeds_rpm, dtype=float) * (2.0 * np.pi / 60.0)
    settings = _settings(cfg_or_models) if not isinstance(cfg_or_models, Sequence) else _HBSettings()
    return np.stack([_row_for_model(m, omegas, settings) for m in models])
