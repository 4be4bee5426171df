r"""Jumps of the nonlinear force at state-dependent instants (contact loss and regain).

A system may declare ``event_functions(s, q, qd, p, xp)``: scalar functions ``e_r`` of the
state across whose zeros ``Q_nl`` may jump (e.g. a friction load that exists only while two
surfaces touch). Sampled uniformly, such a jump aliases at ``O(1/N)`` like a jump at a known
phase, but its instant moves with the solution. Here, from the Fourier coefficients of the state:

1. the zeros of each ``e_r(t)`` over the base period are bracketed by the sign changes on the
   ``N`` AFT samples and, for a short excursion between two samples that carries no sign change
   (the birth of a contact loss), by the extremum of ``e_r`` between them where its value there
   has the other sign (the sampled extrema examined are those whose parabola through the three
   samples comes nearest to, or past, zero); they are located by Newton steps safeguarded by bisection in the bracket
   on the trigonometric polynomial (the state at any ``t`` is exact), so ``t_c`` is smooth in the coefficients and a
   pulse shrinks to nothing continuously;
2. the jump ``J_c = Q_nl(t_c + eps) - Q_nl(t_c - eps)`` (``eps`` = :data:`SIDE`) is measured, and
   the jump ``K_c`` of its time derivative ``dQ_nl/dt`` (a contact force is continuous but kinked
   where it opens: ``k h`` with ``h`` through zero);
3. ``J_c (B_hat_c - P B_c) + K_c (C_hat_c - P C_c)`` is added to the projection,
   ``B_c(t) = 1/2 - frac(t - t_c)`` the unit sawtooth and ``C_c`` its zero-mean integral (exact
   coefficients ``B_hat_c``, ``C_hat_c``; ``P B_c``, ``P C_c`` those of their samples), as for the
   jumps at the breakpoints in :meth:`hbgear.engine.hb.HarmonicBalance._sample_points`.

The corrected projection is continuous in the coefficients (a sample crossing ``t_c`` changes
``P Q_nl`` and ``J_c P B_c`` alike) and errs at ``O(1/N^3)`` near the zeros; its derivative
(through ``t_c``, ``J_c`` and ``K_c``) from ``2 ndof`` directional derivatives of the per-zero
contributions (:func:`jump_jacobian`; ``K_c``'s dependence on ``q''`` at ``t_c`` is left out
of it, a relative ``O(1/N^2)`` of the correction). The slope correction matters where a contact
loss is born between two samples: the force removed over a pulse of width ``w`` is ``O(w^2)``
(its ends are a jump ``c h'`` each, ``+-sqrt`` of the pulse's depth, and a steep ramp between),
and with the jumps alone the ramp, unseen by the samples, left an error ``O(sqrt(depth)/N)``:
a residual with an infinite derivative at the birth. (A jump that stays finite as the pulse is
born -- a load switched off at a finite value -- gives the exact residual itself such a
derivative; no correction removes that.) The kinks at the system's known breakpoints are
corrected with them (:func:`_with_breakpoint_kinks`; their jumps are the discretisation's), so a
kink that the state moves onto a breakpoint stays corrected there. At most the system's
``event_zero_capacity`` (default :data:`MAX_CROSSINGS`, :data:`MAX_EXCURSIONS`) sign changes (the
first in time) and excursions per function and base period are corrected; more stay
``O(1/N)``, and the residual then jumps where the set of corrected zeros changes (a Newton
corrector cannot converge across such a jump).
"""

from __future__ import annotations


import jax
import jax.numpy as jnp
import numpy as np

from . import fourier
from .persistent import persistent
from .typed_jit import typed_jit

__all__ = ["MAX_CROSSINGS", "MAX_EXCURSIONS", "SIDE", "breakpoint_instants", "declared", "crossings", "crossings_compiled",
           "jump_correction", "jump_jacobian", "state_at"]

#: Sign changes located per event function and base period, by default (a system's
#: ``event_zero_capacity`` may raise it: each located zero costs its share of every evaluation; with
#: 32 and 4 a continuation point of the backlash pair with friction cost 3.6 times as much).
MAX_CROSSINGS = 8
#: Excursions between two samples (two zeros each) located per event function and base period, by default.
MAX_EXCURSIONS = 2
#: Half-width of the base-period interval across which a jump is measured.
SIDE = 1e-10
_NEWTON_STEPS = 6
_BRACKET_STEPS = 16


def declared(system, p) -> bool:
    """True when the system declares event functions, probed at one dummy state by tracing only
    (``jax.eval_shape``: nothing is compiled or run -- called eagerly, the probe of the gear pair
    compiled eight small programs, 0.2 s of a command; inside a trace it costs nothing anyway)."""
    def probe(s, q):
        return system.event_functions(s, q, q, p, jnp)

    if not isinstance(p, jax.core.Tracer):
        real = jax.dtypes.canonicalize_dtype(np.float64)
        shapes = jax.ShapeDtypeStruct((1,), real), jax.ShapeDtypeStruct((system.ndof, 1), real)
        try:
            return jax.eval_shape(probe, *shapes) is not None
        except Exception:  # noqa: BLE001 -- a system that reads its arguments' values: probe them
            pass
    zero = jnp.zeros((system.ndof, 1))
    return probe(jnp.zeros(1), zero) is not None


def state_at(xc, vc, t):
    """``(q, q')`` at base fractions `t` (flat, shape ``(m,)``) from real coefficients
    `xc`, `vc` ``(ndof, 2H+1)``: shapes ``(ndof, m)``."""
    k = jnp.arange(1, (xc.shape[-1] - 1) // 2 + 1)
    angle = 2 * np.pi * t[None] * k[:, None]  # (H, m)
    basis = jnp.concatenate([jnp.ones_like(t)[None], jnp.stack([jnp.cos(angle), jnp.sin(angle)], axis=1).reshape(-1, t.shape[0])])
    return xc @ basis, vc @ basis


def _own_events(system, p, xc, vc, nu, t):
    """Event function ``r`` at the base fractions ``t[r]``: `t` ``(E, K)`` -> ``(E, K)``."""
    count = t.shape[0]
    q, qd = state_at(xc, vc, t.ravel())
    values = jnp.reshape(system.event_functions(jnp.mod(t.ravel() * nu, 1.0), q, qd, p, jnp), (count, count, -1))
    rows = jnp.arange(count)
    return values[rows, rows]


def _newton(f, t, lo, hi):
    """Newton steps for ``f(t) = 0`` (elementwise), clipped to ``[lo, hi]`` (the extremum search).

    A ``fori_loop``, so ``f`` (the system's event functions) is traced and compiled once, not once
    per step."""

    def step(_, t):
        value, slope = jax.jvp(f, (t,), (jnp.ones_like(t),))
        return jnp.clip(t - value / jnp.where(slope != 0, slope, 1.0), lo, hi)

    real = jnp.result_type(float)  # a strongly typed carry (the start may be an integer / weak type)
    return jax.lax.fori_loop(0, _NEWTON_STEPS, step, jnp.asarray(t, real))


def _bracketed_zero(f, t, lo, hi):
    """The zero of ``f`` in ``[lo, hi]`` (``f(lo)``, ``f(hi)`` of opposite signs), elementwise:
    Newton steps that fall outside the shrinking bracket are replaced by bisection, so a zero
    just outside the bracket cannot capture the iteration (a ``fori_loop``, as :func:`_newton`)."""

    def bisect_or_step(_, state):
        t, lo, hi, f_lo = state
        value, slope = jax.jvp(f, (t,), (jnp.ones_like(t),))
        low_side = (value > 0) == (f_lo > 0)
        lo, hi = jnp.where(low_side, t, lo), jnp.where(low_side, hi, t)
        f_lo = jnp.where(low_side, value, f_lo)
        step = t - value / jnp.where(slope != 0, slope, 1.0)
        return jnp.where((step >= lo) & (step <= hi), step, 0.5 * (lo + hi)), lo, hi, f_lo

    real = jnp.result_type(float)
    start = tuple(jnp.asarray(x, real) for x in (t, lo, hi, f(lo)))
    return jax.lax.fori_loop(0, _BRACKET_STEPS, bisect_or_step, start)[0]


def crossings(system, p, xc, vc, nu: int, samples: int):
    """Zeros of the system's event functions over one base period.

    **Arguments:** `xc`, `vc`: real coefficients of ``q`` and ``q'``, shape ``(ndof, 2H+1)``;
    `nu`: mesh periods per base period; `samples`: the AFT samples ``N`` that bracket the zeros.

    **Returns:** ``(t, valid)``, shapes ``(E, K)`` (``K = crossings + 2 excursions`` of the
    system's ``event_zero_capacity``):
    base fractions in [0, 1] of the zeros of each function and which entries are zeros (the rest
    padding); ``None`` when the system declares no event functions.
    """
    # the zeros enter the residual as constants (its callers stop their gradients): no tangents
    # are carried through the search, whatever transformation the caller is under
    xc, vc, p = jax.lax.stop_gradient(xc), jax.lax.stop_gradient(vc), jax.lax.stop_gradient(p)
    grid = jnp.arange(samples) / samples
    harmonics = (xc.shape[-1] - 1) // 2
    q = fourier.synthesize(xc, harmonics, samples, jnp)
    qd = fourier.synthesize(vc, harmonics, samples, jnp)
    values = system.event_functions(jnp.mod(grid * nu, 1.0), q, qd, p, jnp)
    if values is None:
        return None
    e = jax.lax.stop_gradient(jnp.reshape(values, (-1, samples)))
    after, before = jnp.roll(e, -1, axis=1), jnp.roll(e, 1, axis=1)
    positive = e > 0

    def first(mask, size):
        index = jax.vmap(lambda row: jnp.nonzero(row, size=size, fill_value=-1)[0])(mask)
        return jnp.where(index >= 0, index, 0), index >= 0

    # sign changes between samples i and i+1
    max_crossings, max_excursions = getattr(system, "event_zero_capacity", (MAX_CROSSINGS, MAX_EXCURSIONS))
    i, valid = first(positive != (after > 0), max_crossings)
    e0, e1 = jnp.take_along_axis(e, i, axis=1), jnp.take_along_axis(after, i, axis=1)
    lo, hi = i / samples, (i + 1) / samples
    step = jnp.where(e0 != e1, e0 - e1, 1.0)
    t = jnp.clip(lo + jnp.clip(e0 / step, 0.0, 1.0) / samples, lo, hi)

    # excursions: a sample that is an extremum of its neighbours, all three of one sign; of
    # those, the ones whose parabola through the three samples reaches nearest to (or past)
    # zero, relative to the samples' size (the first in time would be any wiggle of e_r)
    rising, falling = e - before, after - e
    same = (positive == (before > 0)) & (positive == (after > 0))
    extremum = same & (rising * falling < 0)
    curvature = 0.5 * (after + before) - e
    vertex = e - (0.5 * (after - before)) ** 2 / (4.0 * jnp.where(curvature != 0, curvature, 1.0))
    reach = jnp.where(extremum, jnp.where(positive, vertex, -vertex) / (jnp.abs(e) + jnp.abs(curvature)), jnp.inf)
    _, j = jax.lax.top_k(-reach, max_excursions)
    candidate = jnp.take_along_axis(extremum, j, axis=1)
    j = jnp.where(candidate, j, 0)
    ext_lo, ext_hi = (j - 1) / samples, (j + 1) / samples
    slope_of = lambda tt: jax.jvp(lambda u: _own_events(system, p, xc, vc, nu, u), (tt,), (jnp.ones_like(tt),))[1]  # noqa: E731
    peak = jax.lax.stop_gradient(_newton(slope_of, j / samples, ext_lo, ext_hi))
    flips = (_own_events(system, p, xc, vc, nu, peak) > 0) != jnp.take_along_axis(positive, j, axis=1)
    excursion = candidate & jax.lax.stop_gradient(flips)

    def guess(a, b):  # the zero between a and b by linear interpolation of e
        fa, fb = _own_events(system, p, xc, vc, nu, a), _own_events(system, p, xc, vc, nu, b)
        ratio = jax.lax.stop_gradient(jnp.clip(fa / jnp.where(fa != fb, fa - fb, 1.0), 0.0, 1.0))
        return a + ratio * (b - a)

    lo = jnp.concatenate([lo, ext_lo, peak], axis=1)
    hi = jnp.concatenate([hi, peak, ext_hi], axis=1)
    t = jnp.concatenate([t, guess(ext_lo, peak), guess(peak, ext_hi)], axis=1)
    t = _bracketed_zero(lambda u: _own_events(system, p, xc, vc, nu, u), jax.lax.stop_gradient(t), lo, hi)
    return t, jnp.concatenate([valid, excursion, excursion], axis=1)


def _crossings(system, p, xc, vc, nu: int, samples: int):
    return crossings(system, p, xc, vc, nu, samples)


#: :func:`crossings` compiled (the system a pytree argument), for read-outs point by point; its
#: traced programs kept on disk when a directory is enabled (:mod:`hbgear.engine.persistent`).
crossings_compiled = persistent(typed_jit(_crossings, static_argnums=(4, 5)), "events-crossings",
                                "engine.events.crossings", static_argnums=(4, 5))


def _sampled_projections(t, harmonics: int, samples: int):
    """``(P B_c, P C_c)``, each ``(C, 2H+1)``: the projections of the samples of the sawtooths
    ``B_c(t) = 1/2 - u`` (unit jump at ``t_c``) and of their zero-mean integrals
    ``C_c(t) = -u^2/2 + u/2 - 1/12`` (unit jump of the slope at ``t_c``), ``u = frac(t - t_c)``,
    at base fractions `t` ``(C,)``.

    Between sample instants the samples of ``B_c`` grow with ``t_c`` at slope 1 and those of
    ``C_c`` at slope ``-B_c``, so ``d(P B_c)/dt_c`` is the unit mean and ``d(P C_c)/dt_c = -P B_c``:
    given explicitly, forward-mode derivatives skip the FFT.
    """
    fixed = jax.lax.stop_gradient(t)
    u = jnp.mod(jnp.arange(samples)[None] / samples - fixed[:, None], 1.0)
    both = fourier.project(jnp.stack([0.5 - u, u * (0.5 - 0.5 * u) - 1.0 / 12.0]), harmonics, jnp)
    mean = jnp.zeros(2 * harmonics + 1).at[0].set(1.0)
    shift = (t - fixed)[:, None]
    return both[0] + shift * mean[None], both[1] - shift * both[0]


def _basis(t, harmonics: int):
    """Real basis rows ``[1, cos 2 pi k t, sin 2 pi k t, ...]`` at base fractions `t` ``(C,)``: ``(C, 2H+1)``."""
    angle = 2 * np.pi * t[:, None] * jnp.arange(1, harmonics + 1)[None]
    return jnp.concatenate([jnp.ones_like(t)[:, None], jnp.stack([jnp.cos(angle), jnp.sin(angle)], axis=-1)
                            .reshape(t.shape[0], 2 * harmonics)], axis=1)


def _contributions(system, p, extra, xc, vc, located, shift_q, shift_v, harmonics: int, nu: int, samples: int,
                   slope_q=None, slope_v=None):
    """``J_c (B_hat_c - P B_c) + K_c (C_hat_c - P C_c)`` per zero, shape ``(C, ndof, 2H+1)``, for
    the state shifted near each zero by ``shift_q``, ``shift_v`` and its rate of change in time
    (per unit base fraction) by ``slope_q``, ``slope_v``, each ``(ndof, E, K)`` (zero or ``None``:
    the solution itself).

    The zero is moved by one Newton step on the shifted state from its located value, which
    carries the implicit derivative ``dt_c = -de / e'``; the jumps are measured across it.
    `located` ``(t, valid, weight)``: ``weight`` 0 marks a fixed breakpoint of
    :func:`_with_breakpoint_kinks` (not moved, its kink only, times its weight).
    """
    t0, valid, weight = located
    event = weight == 0.0
    weight = jnp.where(event, 1.0, weight)
    count = t0.shape[0]

    def own(t):
        q, qd = state_at(xc, vc, t.ravel())
        q, qd = q + shift_q.reshape(q.shape), qd + shift_v.reshape(qd.shape)
        values = jnp.reshape(system.event_functions(jnp.mod(t.ravel() * nu, 1.0), q, qd, p, jnp), (count, count, -1))
        rows = jnp.arange(count)
        return values[rows, rows]

    value, slope = jax.jvp(own, (t0,), (jnp.ones_like(t0),))
    t = (t0 - jnp.where(valid & event, value / jnp.where(slope != 0, slope, 1.0), 0.0)).ravel()
    sides = jnp.concatenate([t + SIDE, t - SIDE])
    def both_sides(a):
        return 0.0 if a is None else jnp.tile(a.reshape(xc.shape[0], -1), 2)

    shift_q2, shift_v2, slope_q2, slope_v2 = (both_sides(a) for a in (shift_q, shift_v, slope_q, slope_v))

    def force_at(u):  # Q_nl along the solution at base fractions u (the shifted state)
        q, qd = state_at(xc, vc, u)
        du = u - jax.lax.stop_gradient(u)  # zero, with a unit derivative: the slopes' lever
        q, qd = q + shift_q2 + du * slope_q2, qd + shift_v2 + du * slope_v2
        return system.force(jnp.mod(u * nu, 1.0), q, qd, p, "nonlinear", extra, jnp)

    force, rate = jax.jvp(force_at, (sides,), (jnp.ones_like(sides),))  # Q_nl and dQ_nl/dt
    size = t.shape[0]
    mask = valid.ravel()[None]
    jump = jnp.where(mask & event.ravel()[None], force[:, :size] - force[:, size:], 0.0)  # (ndof, C)
    kink = jnp.where(mask, rate[:, :size] - rate[:, size:], 0.0) * weight.ravel()[None]
    k = jnp.arange(1, harmonics + 1)
    angle = 2 * np.pi * t[:, None] * k[None]
    sin, cos = jnp.sin(angle), jnp.cos(angle)

    def real(a, b):
        return jnp.concatenate([jnp.zeros((size, 1)), jnp.stack([a, b], axis=-1).reshape(size, 2 * harmonics)], axis=1)

    exact = real(-sin / (np.pi * k), cos / (np.pi * k))
    exact2 = real(-cos / (2 * (np.pi * k) ** 2), -sin / (2 * (np.pi * k) ** 2))
    sawtooth, parabola = _sampled_projections(t, harmonics, samples)
    return (jump.T[:, :, None] * (exact - sawtooth)[:, None]
            + kink.T[:, :, None] * (exact2 - parabola)[:, None])


def breakpoint_instants(breakpoints, nu: int, xp=np):
    """Phase 0 and the mesh-phase `breakpoints`, once in each of the ``nu`` mesh periods of the
    base period: ``(s_c, t_c, weight)``, each ``(nu (B + 1),)`` -- mesh phases, base fractions
    ``t_c = (s_c + j) / nu`` and ``1 / multiplicity`` (a phase listed twice counts once)."""
    phase = xp.mod(xp.concatenate([xp.zeros(1), breakpoints]), 1.0)
    gap = xp.abs(phase[:, None] - phase[None, :])
    weight = 1.0 / xp.sum(xp.minimum(gap, 1.0 - gap) < 1e-12, axis=1)
    t_c = ((phase[None, :] + xp.arange(nu)[:, None]) / nu).ravel()
    return xp.tile(phase, nu), t_c, xp.tile(weight, nu)


def _with_breakpoint_kinks(system, p, located, nu: int):
    """The located zeros ``(t, valid)`` ``(E, K)`` joined by the system's known breakpoints (and
    phase 0) as kinks to correct: ``(t, valid, weight)`` ``(E, K + nu B)``, the breakpoints in row 0
    with ``weight = 1 / multiplicity`` (a phase listed twice counts once), every zero with 0.

    The jumps of ``Q_nl`` at the breakpoints are corrected by the discretisation
    (:meth:`hbgear.engine.hb.HarmonicBalance._sample_points`); their kinks are corrected here, for
    systems with event functions, so that a kink which moves with the state onto a breakpoint
    (a pair that opens just as it leaves the path of contact) stays corrected when it gets there:
    with the kinks at the zeros corrected and those at the breakpoints not, the residual stepped
    by the kink's ``O(1/N^2)`` correction where a zero crossed a breakpoint, and a Newton
    corrector stalled there.
    """
    t, valid = located
    _, t_b, w_b = breakpoint_instants(jnp.ravel(jnp.asarray(system.breakpoints(p, jnp))), nu, jnp)
    rows = t.shape[0]
    first = jnp.arange(rows)[:, None] == 0
    t_all = jnp.concatenate([t, jnp.broadcast_to(t_b, (rows, t_b.shape[0]))], axis=1)
    valid_all = jnp.concatenate([valid, jnp.broadcast_to(first, (rows, t_b.shape[0]))], axis=1)
    weight_all = jnp.concatenate([jnp.zeros(t.shape), jnp.broadcast_to(w_b, (rows, t_b.shape[0]))], axis=1)
    return jax.lax.stop_gradient(t_all), valid_all, jax.lax.stop_gradient(weight_all)


def jump_correction(system, p, extra, xc, vc, harmonics: int, nu: int, samples: int):
    """``sum_c J_c (B_hat_c - P B_c)``: real coefficients ``(ndof, 2H+1)`` to add to the projection
    of ``Q_nl`` for its jumps at the zeros of the event functions (zero without any)."""
    located = crossings(system, p, xc, vc, nu, samples)
    if located is None:
        return jnp.zeros(xc.shape)
    located = _with_breakpoint_kinks(system, p, jax.lax.stop_gradient(located), nu)
    shift = jnp.zeros((xc.shape[0],) + located[0].shape)
    return jnp.sum(_contributions(system, p, extra, xc, vc, located, shift, shift, harmonics, nu, samples), axis=0)


def jump_jacobian(system, p, extra, xc, vc, harmonics: int, nu: int, samples: int):
    """Derivatives of :func:`jump_correction` with respect to the coefficients of ``q`` and of
    ``q'``: two arrays ``(ndof, ndof, 2H+1, 2H+1)`` (row coordinate, column coordinate, row
    coefficient, column coefficient), or ``None`` without event functions.

    The correction depends on the coefficients only through the state near each zero and its
    rate of change there (``x(t) = x @ basis(t)``, ``x'(t) = x @ basis'(t)``, the same over the
    ``2 SIDE`` of a jump), so each block is ``sum_c [dC_c/d(state_j) basis(t_c) + dC_c/d(rate_j)
    basis'(t_c)]``: ``4 ndof`` directional derivatives of the per-zero contributions instead of
    one per coefficient.
    """
    located = crossings(system, p, xc, vc, nu, samples)
    if located is None:
        return None
    located = _with_breakpoint_kinks(system, p, jax.lax.stop_gradient(located), nu)
    n = xc.shape[0]
    zero = jnp.zeros((n,) + located[0].shape)
    t_c = located[0].ravel()
    basis = _basis(t_c, harmonics)  # (C, 2H+1)
    rate = jax.jvp(lambda u: _basis(u, harmonics), (t_c,), (jnp.ones_like(t_c),))[1]  # d basis / dt

    def contributions(shift_q, shift_v, slope_q, slope_v):
        return _contributions(system, p, extra, xc, vc, located, shift_q, shift_v, harmonics, nu, samples,
                              slope_q, slope_v)

    # one linearisation, pushed along the 4 ndof unit directions at once (one traced copy of it)
    _, linear = jax.linearize(contributions, zero, zero, zero, zero)
    units = jnp.eye(4 * n).reshape(4 * n, 4, n)[..., None, None] * jnp.ones(located[0].shape)  # (4 ndof, 4, ndof, E, K)
    d = jax.vmap(lambda u: linear(u[0], u[1], u[2], u[3]))(units)  # (4 ndof, C, ndof, 2H+1)
    d = d.reshape(4, n, *d.shape[1:])  # (shift_q, shift_v, slope_q, slope_v), column coordinate
    at = jnp.einsum("kjcib,cd->kijbd", d[:2], basis) + jnp.einsum("kjcib,cd->kijbd", d[2:], rate)
    return at[0], at[1]  # each (ndof_row, ndof_col, 2H+1, 2H+1)
