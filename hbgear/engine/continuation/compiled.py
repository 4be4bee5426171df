"""The compiled corrector: the continuation step as one JAX program (``jit_step``).

It is the compiled twin of :mod:`.corrector` (the engine's Newton on the bordered system
``R(y) = 0``, ``row . y = target``), plus the chord mode and segments of up to
:data:`SEGMENT_POINTS` regular continuation steps in one call.
"""

from __future__ import annotations

import numpy as np

from .corrector import CHORD_ITERATION_WORK, _failure, _Point
from .steps import _grown_step, _limited_step

#: Regular steps one call of the compiled corrector may take in a row (:meth:`_Compiled.segment`).
SEGMENT_POINTS = 32


def _running(condition, count):
    """``condition & (count >= 0)`` for a ``lax.while_loop`` whose `count` never goes negative.

    The second, always true, term makes the loop condition read two loop variables. XLA's
    while-loop passes look for an induction variable whenever the condition reads only one;
    they then extract and clone everything that computes it in the loop body, here the whole
    corrector, several times per compilation (a third of the HLO-pass time of the gear pair's
    program). With two variables the search stops at the condition.
    """
    return condition & (count >= 0)


def _jit_corrector(residual_and_jacobians, residual, size):
    """The corrector of :func:`_python_corrector`, and the regular continuation steps around it,
    as one compiled JAX function (``advance``), and ``no_factor`` (an unusable chord LU).

    One corrector loop turn = one ``(R, R_z, R_p)`` evaluation at a candidate; ``mode`` says
    what the candidate is: 0 the predictor (taken as it is), 1 a full Newton step (taken if it
    decreases ``max |R|``, else a residual-only backtracking gives the next candidate), 2 the
    result of a backtracking (taken as it is), 3 a chord step. ``status``: -1 running, 0
    converged, 1 non-finite residual, 2 singular bordered Jacobian, 3 not converged in
    ``max_iter``. Each callable is traced once, whatever the number of iterations or steps; the
    parameter scale ``p_ref`` is an argument (a new range does not recompile).
    """
    import jax
    import jax.numpy as jnp

    unit_last = np.zeros(size + 1)
    unit_last[-1] = 1.0

    def no_factor(previous, xp=jnp):
        return (xp.zeros((size + 1, size + 1)), xp.zeros(size + 1, np.int32), xp.zeros(size + 1), previous,
                xp.asarray(False))

    def attempt(y_pred, row, target, previous, max_iter, tolerance, factor, scale, args):
        """One corrector run from ``y_pred`` on ``R(y) = 0``, ``row . y = target``:
        ``(y, max|R|, Newton iterations, chord iterations, status, tangent, factor)``; `factor`
        is the LU ``(lu, piv, v, previous_f, usable)`` of the last converged point, for the chord
        mode, and comes back as the LU at ``y`` when converged.

        Chord: modified Newton with ``B = [J_f; row]`` from the LU of ``A = [J_f; previous_f]``:
        ``B = A + e d^T``, ``d = row - previous_f``, so ``B^-1 b = u - v (d . u) / (1 + d . v)``,
        ``u = A^-1 b``, ``v = A^-1 e`` (the unnormalised tangent). Each chord step must halve
        ``max |R|``; on convergence one mode-0 turn evaluates the Jacobian there (for the
        tangent), on failure the Newton iteration restarts from the predictor.
        """
        # The callables are traced in (z, p, *args): `args` are arguments of the compiled program
        # (the gear pair and its quadrature for hbgear.engine.hb.residual_functions),
        # whatever they close over is a constant in it.
        def evaluate(y):
            r, jz, jp = residual_and_jacobians(y[:-1], y[-1] * scale, *args)
            jac = jnp.concatenate([jnp.asarray(jz, dtype=float).reshape(size, size),
                                   scale * jnp.asarray(jp, dtype=float).reshape(size, 1)], axis=1)
            return jnp.asarray(r, dtype=float).reshape(size), jac

        def residual_of(y):
            return jnp.asarray(residual(y[:-1], y[-1] * scale, *args), dtype=float).reshape(size)

        def tangent(jac, previous):
            """Unit tangent from ``[J; previous] t = e``, and that LU (``ok`` = it is usable)."""
            lu, piv = jax.scipy.linalg.lu_factor(jnp.concatenate([jac, previous[None]], axis=0))
            raw = jax.scipy.linalg.lu_solve((lu, piv), unit_last)
            ok = jnp.all(jnp.isfinite(raw))
            t = jax.lax.cond(ok, lambda: raw, lambda: jnp.linalg.svd(jac)[2][-1])
            t = t / jnp.linalg.norm(t)
            return jnp.where(t @ previous >= 0, t, -t), (lu, piv, raw, previous, ok)

        lu, piv, v, previous_f, usable = factor
        d = row - previous_f
        denominator = 1.0 + d @ v

        def constraint_ok(y):
            return jnp.abs(row @ y - target) <= 1e-12 * (1 + jnp.abs(target))

        def chord_step(y, r):
            u = jax.scipy.linalg.lu_solve((lu, piv), -jnp.append(r, row @ y - target))
            return y + u - v * (d @ u) / denominator

        def chord(s):
            cand = chord_step(s["y"], s["r"])
            r = residual_of(cand)
            norm = jnp.max(jnp.abs(r))
            it = s["it"] + 1
            contracted = jnp.isfinite(norm) & (norm <= 0.5 * s["norm"])
            done = contracted & (norm <= tolerance) & constraint_ok(cand)
            # linear convergence at the observed rate: the next step will be converged, so take it
            # and evaluate (R, R_z, R_p) there at once (the Jacobian is needed for the tangent)
            last = contracted & ~done & (norm * (norm / s["norm"]) <= 0.5 * tolerance) & (it < max_iter)
            go_on = contracted & ~done & ~last & (it < max_iter)
            restart = ~done & ~go_on & ~last  # back to the predictor, Newton
            cand = jnp.where(last, chord_step(cand, r), cand)
            it = jnp.where(last, it + 1, it)
            # leaving the chord mode: its steps are counted in chord_it, the Newton turns in it
            return {**s, "it": jnp.where(go_on, it, 0).astype(jnp.int32), "y": jnp.where(restart, s["y"], cand),
                    "r": r, "norm": jnp.where(restart | last, jnp.inf, norm), "cand": jnp.where(restart, y_pred, cand),
                    "mode": jnp.where(go_on, 3, 0).astype(jnp.int32),
                    "chord_it": jnp.where(go_on, 0, it).astype(jnp.int32)}

        def newton(s):
            r_c, jac_c = evaluate(s["cand"])
            norm_c = jnp.max(jnp.abs(r_c))
            decreased = jnp.isfinite(norm_c) & (norm_c < (1 - 1e-4) * s["norm"])

            def take(_):
                it = s["it"] + jnp.where(s["mode"] == 0, 0, 1)
                y, residual_y = s["cand"], row @ s["cand"] - target
                converged = (norm_c <= tolerance) & constraint_ok(y)
                status = jnp.where(~jnp.isfinite(norm_c), 1,
                                   jnp.where(converged, 0, jnp.where(it >= max_iter, 3, -1))).astype(jnp.int32)

                def newton_step(_):
                    a = jnp.concatenate([jac_c, row[None]], axis=0)
                    step = jnp.linalg.solve(a, -jnp.append(r_c, residual_y))
                    ok = jnp.all(jnp.isfinite(step))
                    return jnp.where(ok, y + step, y), step, jnp.where(ok, -1, 2).astype(jnp.int32)

                cand, step, status = jax.lax.cond(status < 0, newton_step,
                                                  lambda _: (y, s["step"], status), None)
                return {**s, "it": it.astype(jnp.int32), "y": y, "jac": jac_c, "norm": norm_c, "cand": cand,
                        "step": step, "mode": jnp.ones_like(s["mode"]), "status": status}

            def backtrack(_):
                y, step, norm = s["y"], s["step"], s["norm"]

                def ls_cond(c):
                    alpha, ok = c
                    return (alpha > 1 / 8) & ~ok

                def ls_body(c):
                    alpha = 0.5 * c[0]
                    n = jnp.max(jnp.abs(residual_of(y + alpha * step)))
                    return alpha, jnp.isfinite(n) & (n < (1 - 1e-4 * alpha) * norm)

                alpha, _ = jax.lax.while_loop(ls_cond, ls_body, (jnp.asarray(1.0, float), jnp.asarray(False)))
                return {**s, "cand": y + alpha * step, "mode": jnp.full_like(s["mode"], 2)}

            return jax.lax.cond((s["mode"] != 1) | decreased, take, backtrack, None)

        i32 = jnp.int32
        start_chord = usable & (max_iter > 0)
        r0 = jax.lax.cond(start_chord, lambda: residual_of(y_pred), lambda: jnp.zeros(size))
        norm0 = jnp.where(start_chord, jnp.max(jnp.abs(r0)), jnp.inf)
        init = dict(it=jnp.asarray(0, i32), y=y_pred, r=r0, jac=jnp.zeros((size, size + 1)), norm=norm0,
                    cand=y_pred, step=jnp.zeros(size + 1), mode=jnp.where(start_chord, 3, 0).astype(i32),
                    status=jnp.asarray(-1, i32), chord_it=jnp.asarray(0, i32))
        # (`it >= 0` always holds: see _running)
        s = jax.lax.while_loop(lambda s: _running(s["status"] < 0, s["it"]),
                               lambda s: jax.lax.cond(s["mode"] == 3, chord, newton, s), init)
        t, new_factor = jax.lax.cond(s["status"] == 0, lambda: tangent(s["jac"], previous),
                                     lambda: (jnp.full(size + 1, jnp.nan), no_factor(previous)))
        return s["y"], s["norm"], s["it"], s["chord_it"], s["status"], t, new_factor

    @jax.jit
    def advance(y_pred, row, target, previous, max_iter, tolerance, factor, scale, use_chord, y0, t0, ds0, budget,
                controls, args=()):
        """Corrector runs from ``y_pred`` and then, while each is a regular continuation step from
        ``(y0, t0, ds0)`` and fewer than `budget` were taken, the next predictor-corrector steps
        with the step-size control of :func:`continuation` (`controls` = ``ds_min, ds_max,
        max_angle_deg, growth, target_iterations, max_parameter_step, p_end, direction, p_start``
        scaled). Regular: converged, accepted (offset, angle), no fold, not at or past ``p_end``,
        not back past ``p_start``.

        **Returns:** ``(taken, points, (y, t, ds), factor, pending)``: `taken` regular steps,
        `points` their ``(y, t, max|R|, iterations, ds)`` stacked (``SEGMENT_POINTS`` rows,
        the first `taken` valid), the state after them, the chord LU, and ``pending`` = ``[y,
        tangent, max|R|, Newton iterations, chord iterations, status, valid]`` of the last
        corrector run when it was not a regular step (for the caller to decide on; one array:
        one transfer). With ``budget = 0`` it is one plain corrector run.
        """
        ds_min, ds_max, max_angle, growth, target_work, max_dp, p_end, direction, p_start = controls
        m = size + 1
        rows = SEGMENT_POINTS
        state = dict(k=jnp.asarray(0, jnp.int32), y=y0, t=t0, ds=ds0, factor=factor, y_pred=y_pred, row=row,
                     target=target, previous=previous, done=jnp.asarray(False), pending=jnp.zeros(2 * m + 5),
                     y_out=jnp.zeros((rows, m)), t_out=jnp.zeros((rows, m)), info=jnp.zeros((rows, 3)))

        def turn(s):
            f = s["factor"]
            y, norm, newton_it, chord_it, status, t, new_factor = attempt(
                s["y_pred"], s["row"], s["target"], s["previous"], max_iter, tolerance,
                f[:4] + (f[4] & use_chord,), scale, args)
            converged = status == 0
            factor = jax.lax.cond(converged, lambda: new_factor, lambda: s["factor"])
            angle = jnp.degrees(jnp.arccos(jnp.clip(t @ s["t"], -1.0, 1.0)))
            offset = jnp.linalg.norm(y - s["y_pred"])
            ds = s["ds"]
            regular = (converged & ~((offset > ds) & (ds > ds_min)) & ~((angle > max_angle) & (ds > ds_min))
                       & (t[-1] * s["t"][-1] >= 0) & ((y[-1] - p_end) * direction < 0)
                       & ~(((y[-1] - p_start) * direction < 0) & ((s["y"][-1] - p_start) * direction >= 0))
                       & (s["k"] < budget))
            work = newton_it + CHORD_ITERATION_WORK * chord_it
            # the step-size control and the parameter-step limit of continuation()
            ds_next = _grown_step(ds, work, angle, ds_min, ds_max, max_angle, growth, target_work, jnp)
            ds_next = _limited_step(ds_next, t[-1], ds_min, max_dp, jnp)
            y_next = y + ds_next * t
            k = s["k"]
            info = jnp.stack([norm, (newton_it + chord_it).astype(float), ds])
            pending = jnp.concatenate([y, t, jnp.stack([norm, newton_it.astype(float), chord_it.astype(float),
                                                        status.astype(float), 1.0])])
            taken = dict(k=k + 1, y=y, t=t, ds=ds_next, factor=factor, y_pred=y_next, row=t, target=t @ y_next,
                         previous=t, done=k + 1 >= budget, pending=s["pending"],
                         y_out=s["y_out"].at[k].set(y), t_out=s["t_out"].at[k].set(t), info=s["info"].at[k].set(info))
            refused = dict(s, done=jnp.asarray(True), pending=pending, factor=factor)
            return jax.lax.cond(regular, lambda: taken, lambda: refused)

        s = jax.lax.while_loop(lambda s: _running(~s["done"], s["k"]), turn, state)
        return s["k"], (s["y_out"], s["t_out"], s["info"]), (s["y"], s["t"], s["ds"]), s["factor"], s["pending"]

    return advance, no_factor


class _Compiled:
    """One run's use of the compiled corrector: a plain corrector call (``self(...)``, the
    interface of :func:`_python_corrector`) or a :meth:`segment` of regular steps; with `chord`
    it keeps the LU of the last converged point for the next call."""

    def __init__(self, compiled, chord: bool, scale: float, controls=None, args=()):
        import jax

        self._jax = jax
        self.advance, no_factor = compiled
        self.chord, self.scale = bool(chord), float(scale)
        self.controls = tuple(np.float64(c) for c in (np.zeros(9) if controls is None else controls))
        self.last = None
        self.empty = None
        self.no_factor = no_factor
        self.args = tuple(args)

    def _factor(self, previous):
        if self.chord and self.last is not None:
            return self.last
        # "no factorisation": device-resident zeros made once, only `previous` changes
        if self.empty is None:
            self.empty = self.no_factor(self._jax.numpy.asarray(previous, dtype=float))
        return self.empty[:3] + (np.asarray(previous, dtype=float), self.empty[4])

    def _run(self, y_pred, row, target, previous, max_iter, tolerance, y0, t0, ds0, budget):
        return self.advance(y_pred, row, float(target), previous, int(max_iter), float(tolerance),
                            self._factor(previous), self.scale, self.chord, y0, t0, float(ds0), int(budget),
                            self.controls, self.args)

    def _result(self, pending, factor, max_iter):
        """A corrector run's packed outcome -> _Point | _Failure (keeps the LU if converged)."""
        m = (pending.size - 5) // 2
        y, t = pending[:m], pending[m : 2 * m]
        norm, newton_it, chord_it, status = float(pending[-5]), int(pending[-4]), int(pending[-3]), int(pending[-2])
        if status == 0:
            self.last = factor
            return _Point(y, norm, t, newton_it + chord_it, newton_it + CHORD_ITERATION_WORK * chord_it)
        return _failure(status, norm, newton_it + chord_it, max_iter)

    def __call__(self, y_pred, row, target, previous, max_iter, tolerance):
        y_pred = np.asarray(y_pred, dtype=float)
        _, _, _, factor, pending = self._run(y_pred, row, target, previous, max_iter, tolerance, y_pred,
                                             np.asarray(row, dtype=float), 0.0, 0)
        return self._result(np.asarray(self._jax.device_get(pending)), factor, max_iter)

    def segment(self, y, t, ds, max_iter, tolerance, budget):
        """Up to `budget` regular steps from ``(y, t, ds)`` in one call.

        **Returns:** ``(points, pending, (y, t, ds))``: the regular points as ``(y, t, max|R|,
        iterations, ds)``, then the outcome of the corrector run that was not a regular step
        (``None`` if the budget ran out first) and the state it started from.
        """
        y_pred = y + ds * t
        taken, (y_out, t_out, info), state, factor, pending = self._run(
            y_pred, t, t @ y_pred, t, max_iter, tolerance, y, t, ds, min(budget, SEGMENT_POINTS))
        taken, y_out, t_out, info, state, pending = self._jax.device_get((taken, y_out, t_out, info, state, pending))
        points = [(y_out[i], t_out[i], float(info[i, 0]), int(info[i, 1]), float(info[i, 2])) for i in range(int(taken))]
        y, t, ds = np.asarray(state[0]), np.asarray(state[1]), float(state[2])
        if pending[-1] == 0:  # the budget ran out on regular steps
            self.last = factor
            return points, None, (y, t, ds)
        if taken:  # the factor of the last regular point, unless the pending run converged
            self.last = factor
        return points, self._result(np.asarray(pending), factor, max_iter), (y, t, ds)


_JIT_CACHE: dict = {}  # (residual_and_jacobians, residual, size) -> compiled corrector



def _cached_jit_corrector(residual_and_jacobians, residual, size):
    """:func:`_jit_corrector` of these callables, traced once for repeated runs (up to 8 kept)."""
    key = (residual_and_jacobians, residual, size)
    if key not in _JIT_CACHE:
        if len(_JIT_CACHE) >= 8:
            _JIT_CACHE.pop(next(iter(_JIT_CACHE)))
        _JIT_CACHE[key] = _jit_corrector(residual_and_jacobians, residual, size)
    return _JIT_CACHE[key]
