r"""Monodromy matrices of periodic systems: exact for linear ones, variational for any.

The Floquet multipliers of a periodic solution ``q*(t)`` of ``M q'' = Q(s, q, q')`` are the
eigenvalues of the monodromy matrix ``Phi`` of the linearised equations
``M y'' = Q_q(t) y + Q_qd(t) y'`` over one base period, ``x(T) = Phi x(0)``, ``x = (y, y')``.

- **Linear systems** (:func:`monodromy_linear`): the homogeneous coefficients do not depend on
  the solution. Between the breakpoints, fourth-order Magnus steps (two Gauss points per step);
  for ``piecewise_constant_coefficients`` systems one step per segment is exact, so ``Phi`` is
  the exact product of matrix exponentials (the gear pair's LTV formulation A: the paper's
  Eq. 20). Batched over parameter values (one :func:`expm_batched` evaluation).
- **Any system** (:func:`monodromy_variational`): ``Phi' = A(t) Phi`` along the solution,
  ``A = [[0, I], [M^-1 Q_q, M^-1 Q_qd]]`` with ``Q_q``, ``Q_qd`` by ``jax.jacfwd`` of the
  system's force, integrated segment by segment between the breakpoints (never across a jump):
  for a harmonic-balance solution (:func:`state_synthesis`) by Dormand--Prince 5(4) inside one
  compiled program (:mod:`hbgear.engine.dopri`), for any other state function by SciPy's
  DOP853. Its cost does not depend on the number of harmonics.

Limitation: a jump of ``Q`` whose phase the state decides (an unregularised ``sgn``) would need
saltation matrices; smooth laws are treated exactly.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "drop_trivial",
    "expm_batched",
    "monodromy_linear",
    "monodromy_variational",
    "multipliers_linear",
    "state_synthesis",
    "StateSynthesis",
    "variational_multipliers",
]

_SQRT3 = np.sqrt(3.0)
_GAUSS2 = (0.5 - _SQRT3 / 6.0, 0.5 + _SQRT3 / 6.0)

#: Multipliers within this distance of 1 count as the two trivial ones of a free coordinate.
TRIVIAL_TOL = 1e-5

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


def drop_trivial(multipliers, system, tol: float = TRIVIAL_TOL) -> np.ndarray:
    """Remove the (at most two) multipliers within `tol` of 1 of a system with a
    ``free_mean_dof`` (last axis; rows that find fewer keep their largest ones, so the result
    stays rectangular); unchanged for other systems."""
    m = np.asarray(multipliers)
    if system.free_mean_dof is None:
        return m
    flat = m.reshape(-1, m.shape[-1])
    out = []
    for row in flat:
        dist = np.abs(row - 1.0)
        drop = [i for i in np.argsort(dist)[:2] if dist[i] < tol]
        out.append(np.delete(row, drop))
    width = min(len(r) for r in out)
    out = [r[np.argsort(-np.abs(r))][:width] for r in out]
    return np.asarray(out).reshape(m.shape[:-1] + (width,))


def _segments(system, p) -> np.ndarray:
    """Edges in [0, 1] of the phase segments between the system's breakpoints (0 and 1 included)."""
    bp = np.asarray(system.breakpoints(p, np), dtype=float).ravel()
    bp = bp[(bp > 0.0) & (bp < 1.0)]
    return np.unique(np.concatenate([[0.0], bp, [1.0]]))


def _linear_coefficients(system, p, s: np.ndarray):
    """``K(s)``, ``C(s)`` of ``M q'' = F(s) - K q - C q'`` (a linear system), shapes ``(len(s), n, n)``,
    from differences of the force at zero and at unit states (it is affine): one evaluation of the
    force at the ``2n + 1`` states side by side (the gear pair's static wind-up and the model's
    other per-call work once instead of ``2n + 1`` times)."""
    n = system.ndof
    s = np.asarray(s, dtype=float).ravel()
    m = s.size
    q = np.zeros((n, 2 * n + 1, m))
    qd = np.zeros((n, 2 * n + 1, m))
    for j in range(n):
        q[j, 1 + j] = 1.0
        qd[j, 1 + n + j] = 1.0
    f = np.asarray(system.force(np.tile(s, 2 * n + 1), q.reshape(n, -1), qd.reshape(n, -1), p, "linear", 0.0, np),
                   dtype=float).reshape(n, 2 * n + 1, m)
    differences = f[:, :1] - f[:, 1:]  # (n, 2n, m): column j of K, then of C
    stiff = np.transpose(differences[:, :n], (2, 0, 1))
    damp = np.transpose(differences[:, n:], (2, 0, 1))
    return np.ascontiguousarray(stiff), np.ascontiguousarray(damp)


def _state_matrices(system, p, s: np.ndarray, w_ref: float) -> np.ndarray:
    """Balanced first-order ``A(s)`` for ``y = (q, q'/w_ref)``, shape ``(len(s), 2n, 2n)``:
    displacements and scaled velocities of one size, so the eigenvalues of ``Phi`` come out to
    ~1e-14 instead of ~1e-10 (they are similarity invariant)."""
    n = system.ndof
    stiff, damp = _linear_coefficients(system, p, s)
    minv = np.linalg.inv(np.asarray(system.mass_matrix(p, np), dtype=float))
    a = np.zeros((len(s), 2 * n, 2 * n))
    a[:, :n, n:] = w_ref * np.eye(n)
    a[:, n:, :n] = -(minv @ stiff) / w_ref
    a[:, n:, n:] = -minv @ damp
    return a


def _magnus_terms(system, p, substeps: int, w_ref: float, constant: bool = False):
    """Per step ``(P, Q)`` with the Magnus exponent ``Omega = T P + T^2 Q`` over one period ``T``.

    Fourth order, two Gauss points on `substeps` equal sub-steps of every segment between the
    breakpoints; exact (``Q = 0``, one step) for piecewise-constant coefficients, which are then
    (`constant`) evaluated once per segment, at its middle: the two Gauss points see the same
    matrix there (the LTV example's multipliers moved by at most 5e-14, its period-doubling
    speeds by 3e-15 relative), and the zone scan, the curve's exact stability and the
    period-doubling search evaluate the model half as often (the three stages together 0.27-0.37 s
    against 0.34-0.48 s on that example, three alternated runs).
    """
    edges = _segments(system, p)
    left, right = edges[:-1], edges[1:]
    keep = right - left > 1e-14
    left, right = left[keep], right[keep]
    frac = np.arange(substeps) / substeps
    h = np.repeat((right - left) / substeps, substeps)
    left = (left[:, None] + (right - left)[:, None] * frac[None]).ravel()
    if constant:
        a = _state_matrices(system, p, left + 0.5 * h, w_ref)
        return h[:, None, None] * a, np.zeros_like(a)
    a1 = _state_matrices(system, p, left + _GAUSS2[0] * h, w_ref)
    a2 = _state_matrices(system, p, left + _GAUSS2[1] * h, w_ref)
    return 0.5 * h[:, None, None] * (a1 + a2), (_SQRT3 / 12.0) * (h**2)[:, None, None] * (a2 @ a1 - a1 @ a2)


def _reference_frequency(system, p) -> float:
    return float(system.frequency_scale(p))


def _magnus_product(system, ps, period, substeps, w_ref, constant):
    """``Phi`` (balanced) at every parameter of `ps` with `substeps` Magnus steps per segment."""
    pq = _magnus_terms(system, float(ps[0]), substeps, w_ref, constant)
    shared = True
    if ps.size > 1 and not (constant and system.coefficients_independent_of_parameter):
        last = _magnus_terms(system, float(ps[-1]), substeps, w_ref, constant)
        scale = max(np.max(np.abs(pq[0])), 1e-300)
        shared = (np.allclose(pq[0], last[0], rtol=1e-12, atol=1e-14 * scale)
                  and np.allclose(pq[1], last[1], rtol=1e-12, atol=1e-14 * scale**2))
    if shared:
        exponent = period[:, None, None, None] * pq[0][None] + (period**2)[:, None, None, None] * pq[1][None]
    else:  # parameter-dependent coefficients (e.g. a friction law of the sliding speed)
        terms = [_magnus_terms(system, float(p), substeps, w_ref, constant) for p in ps]
        exponent = (period[:, None, None, None] * np.stack([t[0] for t in terms])
                    + (period**2)[:, None, None, None] * np.stack([t[1] for t in terms]))
    steps = expm_batched(exponent)  # (len(ps), steps, 2n, 2n)
    phi = steps[:, 0]
    for k in range(1, steps.shape[1]):
        phi = steps[:, k] @ phi
    return phi


#: Relative change of the balanced monodromy matrix between ``n`` and ``2n`` Magnus sub-steps below
#: which the ``2n`` result is taken (its error is then ~1/16 of that: fourth order).
MAGNUS_TOLERANCE = 1e-11


def monodromy_linear(system, ps, *, substeps: int | None = None, balanced: bool = False) -> np.ndarray:
    """Monodromy matrices over one excitation period ``2 pi / w_exc(p)`` of a linear system,
    batched over parameter values.

    **Arguments:** `system`: a :class:`~hbgear.engine.system.PeriodicSystem` with ``is_linear``;
    `ps`: parameter values, scalar or 1-D; `substeps`: Magnus sub-steps per segment. Default: one
    for ``piecewise_constant_coefficients`` systems (exact); otherwise 16, doubled until the
    result changes by less than :data:`MAGNUS_TOLERANCE` (relative) between ``n`` and ``2n``
    (fourth order: the error is ~1/16 of that change; at most 4096 steps); `balanced`: the matrix
    for ``(q, q'/w_ref)`` instead (same eigenvalues, better conditioned; ``w_ref =
    system.frequency_scale(p)``).

    **Returns:** ``Phi`` with ``x(T) = Phi x(0)``, ``x = (q, q')``; shape ``(len(ps), 2n, 2n)``
    (``(2n, 2n)`` for a scalar).

    **Raises:** ``ValueError`` for a non-linear system (use :func:`monodromy_variational`).
    """
    if not system.is_linear:
        raise ValueError(f"monodromy_linear needs a linear system; {type(system).__name__} is not "
                         "(use monodromy_variational or Hill's method)")
    scalar = np.ndim(ps) == 0
    ps = np.atleast_1d(np.asarray(ps, dtype=float))
    constant = bool(system.piecewise_constant_coefficients)
    w_ref = _reference_frequency(system, float(ps[0]))
    period = 2.0 * np.pi / np.array([float(system.excitation_frequency(p)) for p in ps])
    if substeps is not None or constant:
        phi = _magnus_product(system, ps, period, 1 if substeps is None else substeps, w_ref, constant)
    else:
        n, phi = 16, _magnus_product(system, ps, period, 16, w_ref, constant)
        while n < 4096:
            finer = _magnus_product(system, ps, period, 2 * n, w_ref, constant)
            change = np.max(np.abs(finer - phi)) / max(np.max(np.abs(finer)), 1e-300)
            n, phi = 2 * n, finer
            if change <= MAGNUS_TOLERANCE:
                break
    if not balanced:
        scale = np.concatenate([np.ones(system.ndof), np.full(system.ndof, w_ref)])
        phi = scale[:, None] * phi / scale[None, :]
    return phi[0] if scalar else phi


def multipliers_linear(system, ps, *, substeps: int | None = None, drop: bool = True) -> np.ndarray:
    """Floquet multipliers over one excitation period of a linear system, shape ``(len(ps), 2n')``
    (``2n' = 2n`` less the trivial pair of a free coordinate when `drop`)."""
    scalar = np.ndim(ps) == 0
    mult = np.linalg.eigvals(monodromy_linear(system, np.atleast_1d(ps), substeps=substeps, balanced=True))
    if drop:
        mult = drop_trivial(mult, system)
    return mult[0] if scalar else mult


# ============================================================================ variational


_VARIATIONAL_RHS: dict = {}

#: A batch of variational equations is padded (copies of its last member) to a power of two and
#: at least this many members, so that the period-doubling search's two batches (one member per
#: crossing, then two) share one compiled right-hand side (~0.4 s of tracing each) up to 4 crossings.
VARIATIONAL_BATCH = 8


def _variational_member(system, s, q, qd, p, minv, period, phi):
    """One member's variational right-hand side at phase `s`, ``[Phi_v; M^-1 (Q_q Phi_q + Q_qd
    Phi_v)] * T`` with ``Phi = [Phi_q; Phi_v]`` flattened (traced by JAX)."""
    import jax
    import jax.numpy as jnp

    def force(q, qd):
        return system.force(s, q, qd, p, "all", 0.0, jnp)

    dq, dqd = jax.jacfwd(force, argnums=(0, 1))(q, qd)
    n = q.shape[0]
    phi = phi.reshape(2 * n, 2 * n)
    velocity_rows = minv @ (dq @ phi[:n] + dqd @ phi[n:])
    return (period * jnp.concatenate([phi[n:], velocity_rows])).ravel()


def _variational_rhs(batched: bool = False):
    """The jitted right-hand side at one instant (built once; the system is a pytree argument):
    :func:`_variational_member`. Only the Jacobians of the force enter (constant terms drop out
    of the tangents). One compiled call per evaluation (the ODE solver calls it ~1000 times per
    monodromy, ~30000 for the gear pair at 200 rpm), whose changing inputs come packed in one
    vector ``y = [s, q, q', Phi]`` (one transfer instead of four: ~35 instead of ~55 us a call).
    `batched`: vmapped over the members ``(q, q', p, M^-1, T, Phi)`` of a batch (``y`` holds them
    member after member), the phase and the system shared."""
    if batched not in _VARIATIONAL_RHS:
        import jax

        member = _variational_member

        def rhs(system, p, minv, period, y):
            n = minv.shape[-1]
            if not batched:
                return member(system, y[0], y[1:1 + n], y[1 + n:1 + 2 * n], p, minv, period, y[1 + 2 * n:])
            size = minv.shape[0]
            q = y[1:1 + size * n].reshape(size, n)
            qd = y[1 + size * n:1 + 2 * size * n].reshape(size, n)
            phi = y[1 + 2 * size * n:].reshape(size, -1)
            return jax.vmap(member, in_axes=(None, None, 0, 0, 0, 0, 0, 0))(system, y[0], q, qd, p, minv, period,
                                                                           phi).ravel()

        from .persistent import persistent
        from .typed_jit import typed_jit

        compiled = typed_jit(rhs)
        # it closes over nothing but `batched`: its traced program may be kept on disk
        _VARIATIONAL_RHS[batched] = persistent(compiled, "variational-rhs", ("engine.monodromy._variational_rhs", batched))
    return _VARIATIONAL_RHS[batched]


_VARIATIONAL_PROGRAM: list = []


def _variational_program():
    """The whole batched integration of the variational equations as one compiled program (built
    once): :func:`hbgear.engine.dopri.integrate_segments` over the segments between breakpoints,
    the state ``(q, q')`` synthesised inside from the Fourier coefficients (``Re S e(tau)``), the
    members vmapped. **Returns** ``(Phi (members, 2n, 2n), steps per segment, ok)``."""
    if not _VARIATIONAL_PROGRAM:
        import jax
        import jax.numpy as jnp

        from .dopri import integrate_segments
        from .persistent import persistent
        from .typed_jit import typed_jit

        def integrate(system, ps, minv, period, synthesis_re, synthesis_im, starts, ends, phase_starts, phase_lo,
                      phase_hi, nu, rtol, atol):
            size, n = minv.shape[0], minv.shape[-1]
            orders = 2.0 * jnp.pi * jnp.arange(synthesis_re.shape[-1])

            def f(tau, y, segment):
                start, s_start, lo, hi = segment
                s = jnp.clip(s_start + (tau - start) * nu, lo, hi)
                x = synthesis_re @ jnp.cos(orders * tau) - synthesis_im @ jnp.sin(orders * tau)  # (size, 2n)
                rows = jax.vmap(_variational_member, in_axes=(None, None, 0, 0, 0, 0, 0, 0))(
                    system, s, x[:, :n], x[:, n:], ps, minv, period, y.reshape(size, -1))
                return rows.ravel()

            y0 = jnp.tile(jnp.eye(2 * n).ravel(), size)
            y, steps, ok = integrate_segments(f, y0, starts, ends, (starts, phase_starts, phase_lo, phase_hi),
                                              rtol, atol, max_steps=COMPILED_MAX_STEPS)
            return y.reshape(size, 2 * n, 2 * n), steps, ok

        # it closes over nothing: its traced program may be kept on disk
        _VARIATIONAL_PROGRAM.append(persistent(typed_jit(integrate), "variational-integration",
                                               ("engine.monodromy._variational_program",)))
    return _VARIATIONAL_PROGRAM[0]


def state_synthesis(coefficients, harmonics: int, base_frequency):
    """``tau -> (q, q')`` at the base-period fraction ``tau`` (numpy) from real Fourier
    coefficients ``(..., ndof, 2H+1)`` [``a_0, a_1, b_1, ...``] and base frequencies (scalar or
    ``(...)``): arrays ``(..., ndof)``, from one complex matrix product ``[q; q'] = Re S e(tau)``,
    ``e_k = exp(2 pi i k tau)``, ``k = 0 .. H``, the powers as the outer product of ``~sqrt(H)``
    low and ``~sqrt(H)`` high ones (``2 sqrt(H)`` exponentials per instant instead of ``2H`` sines
    and cosines).

    In numpy, not in the compiled right-hand side: a reduction over the harmonics there makes
    XLA hand the program to its worker thread, which costs more than the whole evaluation."""
    c = np.asarray(coefficients, dtype=float)
    n = c.shape[-2]
    k = np.arange(harmonics + 1)
    w = np.asarray(base_frequency, dtype=float)[..., None, None]
    position = np.concatenate([c[..., :1], c[..., 1::2] - 1j * c[..., 2::2]], axis=-1)  # q = Re sum c_k e^{i k t}
    synthesis = np.concatenate([position + 0.0 * w, 1j * w * k * position], axis=-2)
    low = int(np.ceil(np.sqrt(harmonics + 1)))
    low_orders = 2j * np.pi * np.arange(low)
    high_orders = 2j * np.pi * low * np.arange(-(-(harmonics + 1) // low))

    return StateSynthesis(synthesis, n, harmonics, low_orders, high_orders)


class StateSynthesis:
    """``tau -> (q, q')`` of :func:`state_synthesis`; `synthesis` ``(..., 2n, H+1)`` holds the
    complex coefficients (``[q; q'] = Re synthesis e(tau)``), read by the compiled integration of
    :func:`monodromy_variational`."""

    def __init__(self, synthesis, ndof, harmonics, low_orders, high_orders):
        self.synthesis, self.ndof, self.harmonics = synthesis, ndof, harmonics
        self._low, self._high = low_orders, high_orders

    def __call__(self, tau):
        powers = (np.exp(self._high * tau)[:, None] * np.exp(self._low * tau)[None]).ravel()[: self.harmonics + 1]
        x = (self.synthesis @ powers).real
        return x[..., :self.ndof], x[..., self.ndof:]


def monodromy_variational(system, p, state, nu: int = 1, *, rtol: float = 1e-10, atol: float = 1e-12,
                          integrator: str = "auto") -> np.ndarray:
    """Monodromy matrix over one base period ``nu 2 pi / w_exc(p)`` from the variational equations.

    **Arguments:** `system`: any :class:`~hbgear.engine.system.PeriodicSystem`; `p`: its
    parameter, or a 1-D array of parameters (a batch: one integration of all the members'
    equations together, each evaluation of the right-hand side one vmapped call, so a batch
    costs about one monodromy; members are padded to a power of two, at least
    :data:`VARIATIONAL_BATCH`, so few batch sizes compile); `state`: ``tau -> (q, q')`` along the
    periodic solution(s), ``tau`` the fraction of the base period, arrays ``(ndof,)``
    (``(len(p), ndof)`` for a batch; :func:`state_synthesis` of harmonic-balance solutions); `nu`:
    base period in excitation periods; `rtol`, `atol`: of the integrator on ``Phi`` (a batch of
    ``K`` padded members integrates with ``rtol / sqrt(K)``: its error norm is the RMS over all of
    them, so each member's stays within `rtol`); `integrator`: ``"compiled"`` (Dormand--Prince 5(4)
    inside one compiled program, :mod:`hbgear.engine.dopri`; needs `state` from
    :func:`state_synthesis`), ``"DOP853"`` (SciPy's, the right-hand side called from Python) or
    ``"auto"`` (compiled where `state` allows, DOP853 otherwise and where the compiled one fails).
    On the NLTV gear pair (arctan, H = 32, N = 1024; a batch of 8 speeds over 3000-20000 rpm)
    the compiled integration took 0.022-0.044 s against 0.79-0.90 s for DOP853, the multipliers
    within 3.6e-10 of each other; compiling it takes ~1.9 s once (then kept on disk with the
    other programs, :mod:`hbgear.engine.persistent`).

    **Returns:** ``Phi``, shape ``(2n, 2n)`` (``(len(p), 2n, 2n)``), ``x(T) = Phi x(0)``,
    ``x = (q, q')`` in SI.

    **Raises:** ``RuntimeError`` if the integrator fails on a segment; ``ValueError`` for a batch
    whose members have different breakpoints.
    """
    import jax
    from scipy.integrate import solve_ivp

    batch = np.ndim(p) > 0
    ps = np.atleast_1d(np.asarray(p, dtype=float))
    members = len(ps)
    n = system.ndof
    if integrator not in ("auto", "compiled", "DOP853"):
        raise ValueError(f"monodromy_variational: integrator = {integrator!r}; allowed: 'auto', 'compiled', 'DOP853'")
    # M and the breakpoints of a system that declares them independent of p are those of the first
    # member (per member they were ~0.1 s of the NLTV curve's 0.5 s of stability)
    same_for_all = bool(system.coefficients_independent_of_parameter)
    bp = _segments(system, float(ps[0]))
    if not same_for_all and any(not np.array_equal(_segments(system, float(x)), bp) for x in ps[1:]):
        raise ValueError("monodromy_variational: the members of a batch must have the same breakpoints")
    edges = np.unique(np.concatenate([(j + bp) / nu for j in range(nu)]))
    size = max(VARIATIONAL_BATCH, 1 << (members - 1).bit_length()) if batch else 1  # padded: few programs
    pad = np.minimum(np.arange(size), members - 1)

    def inverse_mass(x):
        return np.linalg.inv(np.asarray(system.mass_matrix(float(x), np), dtype=float))

    if same_for_all:
        minv = np.repeat(inverse_mass(ps[0])[None], size, axis=0)
    else:
        minv = np.stack([inverse_mass(x) for x in ps])[pad]
    base_period = (nu * 2.0 * np.pi / np.array([float(system.excitation_frequency(float(x))) for x in ps]))[pad]
    compiled = integrator == "compiled" or (integrator == "auto" and isinstance(state, StateSynthesis))
    if compiled:
        if not isinstance(state, StateSynthesis):
            raise ValueError("monodromy_variational: integrator = 'compiled' needs `state` from state_synthesis")
        phi = _compiled_monodromy(system, ps[pad], state, edges, nu, minv, base_period, rtol / math.sqrt(size),
                                  atol / math.sqrt(size), members, pad)
        if phi is not None:
            return phi[:members] if batch else phi[0]
        if integrator == "compiled":
            raise RuntimeError("variational equations failed (compiled Dormand-Prince: step size or step count)")
    variational_rhs = _variational_rhs(batch)
    # the arguments that stay the same over the ~1000 calls go to the device once (a Python float
    # or numpy argument is converted at every call: most of the cost of a call before)
    if batch:
        device_system, *constants = jax.device_put((system, ps[pad], minv, base_period))
    else:
        device_system, *constants = jax.device_put((system, float(ps[0]), minv[0], float(base_period[0])))
    phi = np.broadcast_to(np.eye(2 * n), (size, 2 * n, 2 * n)) if batch else np.eye(2 * n)
    template = np.zeros(1 + 2 * size * n + size * (2 * n) ** 2 if batch else 1 + 2 * n + (2 * n) ** 2)
    variational_rhs = variational_rhs.for_arguments(device_system, *constants, template)  # looked up once
    for a, b in zip(edges[:-1], edges[1:]):
        if b - a < 1e-14:
            continue
        # the phases of this segment, kept strictly inside it (one-sided limits at jumps)
        s_lo = (a * nu) % 1.0
        lo, hi = s_lo + 1e-12, min(s_lo + (b - a) * nu, 1.0) - 1e-12

        def rhs(tau, y, lo=lo, hi=hi, start=a, s0=s_lo):
            s = float(np.clip(s0 + (tau - start) * nu, lo, hi))
            q, qd = state(tau)
            if batch:
                q, qd = q[pad], qd[pad]
            packed = np.concatenate([[s], np.ravel(q), np.ravel(qd), y])
            return np.asarray(variational_rhs(device_system, *constants, packed))

        sol = solve_ivp(rhs, (a, b), np.ravel(phi), method="DOP853", rtol=rtol / math.sqrt(size),
                        atol=atol / math.sqrt(size))
        if not sol.success:
            raise RuntimeError(f"variational equations failed on [{a:.6g}, {b:.6g}]: {sol.message}")
        phi = sol.y[:, -1].reshape(phi.shape)
    return phi[:members] if batch else phi


#: Steps per segment at most of the compiled integration (:func:`hbgear.engine.dopri.integrate_segments`).
COMPILED_MAX_STEPS = 100_000


def _compiled_monodromy(system, ps, state, edges, nu, minv, base_period, rtol, atol, members, pad):
    """``Phi`` of the padded batch by :func:`_variational_program`, or ``None`` if it failed."""
    import jax

    synthesis = np.broadcast_to(state.synthesis, (members,) + np.shape(state.synthesis)[-2:]) \
        if np.ndim(state.synthesis) == 2 else np.asarray(state.synthesis)
    synthesis = synthesis[pad]
    a, b = edges[:-1], edges[1:]
    keep = b - a >= 1e-14
    a, b = a[keep], b[keep]
    s_lo = (a * nu) % 1.0
    lo, hi = s_lo + 1e-12, np.minimum(s_lo + (b - a) * nu, 1.0) - 1e-12
    args = jax.device_put((system, ps, minv, base_period, np.ascontiguousarray(synthesis.real),
                           np.ascontiguousarray(synthesis.imag), a, b, s_lo, lo, hi, float(nu), float(rtol),
                           float(atol)))
    phi, _, ok = _variational_program()(*args)
    if not bool(ok):
        return None
    return np.asarray(phi)


def variational_multipliers(hb, system, z, p, *, rtol: float | None = None, atol: float | None = None) -> np.ndarray:
    """Floquet multipliers over the base period of the harmonic-balance solution `z` (scaled
    unknowns of `hb`) at `p` by the variational equations (:func:`monodromy_variational`),
    trivial ones dropped, largest modulus first: the stability of the structured path, whose cost
    does not grow with ``H`` (only the state synthesis per instant does, by ``O(H)``).

    `rtol`, `atol`: the integrator's, by default those of a branch's stability
    (:data:`hbgear.engine.stability.VARIATIONAL_RTOL`, ``VARIATIONAL_ATOL``): the NLTV pair at 200 rpm, H = 2048, its
    multipliers within 9.3e-11 of a run at rtol 1e-12 in 1.6-1.7 s (rtol 1e-10: 7.8e-13, 3.9-4.2
    s), where those of H = 1024 and 2048 differ by 1.4e-8."""
    from .stability import VARIATIONAL_ATOL, VARIATIONAL_RTOL

    coefficients, _ = hb.decode(system, np.asarray(z, dtype=float))
    base_frequency = float(system.excitation_frequency(p)) / hb.nu
    phi = monodromy_variational(system, p, state_synthesis(coefficients, hb.harmonics, base_frequency), hb.nu,
                                rtol=VARIATIONAL_RTOL if rtol is None else rtol,
                                atol=VARIATIONAL_ATOL if atol is None else atol)
    multipliers = drop_trivial(np.linalg.eigvals(phi), system)
    return multipliers[np.argsort(-np.abs(multipliers), kind="stable")]
