r"""An adaptive Runge--Kutta integrator that runs inside one compiled program.

:func:`integrate_segments` integrates ``y' = f(t, y, segment)`` over consecutive intervals
``[a_j, b_j]`` (never stepping across an edge: the right-hand side may jump there) with the
Dormand--Prince 5(4) pair (Dormand & Prince 1980; Hairer, Norsett & Wanner, *Solving ODEs I*,
II.5), local extrapolation (the fifth-order solution is kept), and the step-size control of
Hairer's ``dopri5`` / SciPy's ``RK45``: the error

.. math:: \|e\| = \sqrt{\tfrac{1}{m}\sum_i \Bigl(\frac{e_i}{a + r \max(|y_i|, |y_i^{new}|)}\Bigr)^2}

accepts a step when ``||e|| <= 1``; the next step is ``h min(10, max(0.2, 0.9 ||e||^{-1/5}))``
(at most ``h`` after a rejection). Written for :mod:`jax` (``lax.scan`` over the intervals,
``lax.while_loop`` over the steps, ``lax.fori_loop`` over the stages so that the right-hand side
is traced and compiled once: seven copies of a gear pair's took 4.0 s to compile, one 1.9 s), to be
called inside ``jax.jit``: a whole integration is one compiled call instead of one Python call
of the right-hand side per stage, which is what an ODE solver driven from Python pays (~30-40 us
a call). Every stage is evaluated at every step (no first-same-as-last reuse: that would be a
second copy of the right-hand side in the program).

It knows nothing of the equations: :mod:`hbgear.engine.monodromy` integrates the variational
equations with it.
"""

from __future__ import annotations

__all__ = ["integrate_segments", "DP54_A", "DP54_B", "DP54_C", "DP54_E"]

#: The Dormand--Prince 5(4) tableau: nodes `DP54_C`, stages `DP54_A` (row i: coefficients of
#: the stages before it), fifth-order weights `DP54_B` (= the last row: first same as last) and
#: error weights `DP54_E` (fifth minus fourth order).
DP54_C = (0.0, 1 / 5, 3 / 10, 4 / 5, 8 / 9, 1.0, 1.0)
DP54_A = (
    (),
    (1 / 5,),
    (3 / 40, 9 / 40),
    (44 / 45, -56 / 15, 32 / 9),
    (19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729),
    (9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656),
    (35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84),
)
DP54_B = (35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84, 0.0)
DP54_E = (71 / 57600, 0.0, -71 / 16695, 71 / 1920, -17253 / 339200, 22 / 525, -1 / 40)

_SAFETY, _MIN_FACTOR, _MAX_FACTOR = 0.9, 0.2, 10.0

#: The first step of the first interval, as a fraction of it (the control grows it tenfold a step).
FIRST_STEP = 1e-3


def integrate_segments(f, y0, starts, ends, segment_data, rtol, atol, max_steps: int = 100_000):
    """Integrate ``y' = f(t, y, data_j)`` from ``y0`` over ``[starts[j], ends[j]]``, ``j = 0, 1, ...``
    (each interval from where the last ended; `segment_data`: a pytree whose leaves have the
    intervals on their first axis), traceable by ``jax.jit``.

    **Arguments:** `f(t, y, data)` -> ``y'`` (``y`` a 1-D array); `rtol`, `atol`: of the error
    norm (module docstring); `max_steps`: attempted steps per interval at most.

    **Returns:** ``(y, steps, ok)``: the state at the last end, the attempted steps of every
    interval, and whether every interval reached its end with finite values (``False``: too many
    steps, a step size underflow or a non-finite state; ``y`` is then not to be used).
    """
    import jax.numpy as jnp
    import numpy as np
    from jax import lax

    tableau = np.zeros((7, 7))
    for i, row in enumerate(DP54_A):
        tableau[i, :len(row)] = row
    a, c = jnp.asarray(tableau), jnp.asarray(DP54_C)
    b, e = jnp.asarray(DP54_B), jnp.asarray(DP54_E)

    def stages(t, y, h, data):
        """The seven stages, in a loop: `f` is traced once (its program is compiled once)."""
        def stage(i, ks):
            return ks.at[i].set(f(t + c[i] * h, y + h * (a[i] @ ks), data))

        ks = lax.fori_loop(0, 7, stage, jnp.zeros((7,) + y.shape, dtype=y.dtype))
        return y + h * (b @ ks), h * (e @ ks)

    def interval(carry, segment):
        y, h_prev = carry
        start, end, data = segment
        span = end - start
        h = jnp.where(h_prev > 0, jnp.minimum(h_prev, span), FIRST_STEP * span)

        def cond(state):
            t, _, _, steps, failed, _ = state
            return (t < end) & (steps < max_steps) & ~failed

        def body(state):
            t, y, proposed, steps, failed, keep = state
            h = jnp.minimum(proposed, end - t)
            last = proposed >= end - t
            y_new, err = stages(t, y, h, data)
            scale = atol + rtol * jnp.maximum(jnp.abs(y), jnp.abs(y_new))
            norm = jnp.sqrt(jnp.mean((err / scale) ** 2))
            good = (norm <= 1.0) & jnp.all(jnp.isfinite(y_new))
            factor = jnp.where(norm == 0.0, _MAX_FACTOR, _SAFETY * jnp.maximum(norm, 1e-300) ** -0.2)
            factor = jnp.clip(factor, _MIN_FACTOR, jnp.where(good, _MAX_FACTOR, 1.0))
            factor = jnp.where(jnp.isfinite(norm), factor, _MIN_FACTOR)
            t_new = jnp.where(good, jnp.where(last, end, t + h), t)
            small = h <= 1e-14 * jnp.maximum(jnp.abs(t), jnp.abs(end))
            # the step the next interval starts with: the last proposal before one was cut at the end
            keep = jnp.where(good, jnp.where(last, proposed, h * factor), keep)
            return (t_new, jnp.where(good, y_new, y), h * factor, steps + 1, failed | (~good & small), keep)

        init = (start, y, h, jnp.asarray(0), jnp.asarray(False), h)
        t, y, _, steps, failed, keep = lax.while_loop(cond, body, init)
        ok = (t >= end) & ~failed & jnp.all(jnp.isfinite(y))
        return (y, keep), (steps, ok)

    (y, _), (steps, ok) = lax.scan(interval, (y0, jnp.asarray(0.0, dtype=y0.dtype)), (starts, ends, segment_data))
    return y, steps, jnp.all(ok)
