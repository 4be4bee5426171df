r"""Pseudo-arclength continuation of a solution branch ``R(z; p) = 0`` (any residual).

The branch is followed in the scaled unknowns ``y = (z, p / p_ref)`` so that one arclength step
mixes comparable magnitudes (the harmonic-balance ``z`` are already scaled by the static
deflection; ``p_ref`` defaults to ``max(|p0|, |p_end|)``). Each step:

1. **Tangent** ``t``: the unit null vector of ``[R_z, R_p p_ref]``, from the bordered system
   ``[[R_z, R_p p_ref], [t_prev^T]] t = [0, 1]`` -- which keeps the orientation
   (``t . t_prev > 0``), so the branch is followed through folds.
2. **Predictor** ``y_pred = y + ds t``.
3. **Corrector**: Newton on ``R(y) = 0``, ``t . (y - y_pred) = 0`` (the hyperplane orthogonal to
   the tangent), with a backtracking line search on ``max |R|``; converged when
   ``max |R| <= tolerance``.
4. **Acceptance**: the corrector converged within ``max_corrector_iterations``, moved less than
   ``ds`` off the predictor, and the new tangent turned by at most ``max_angle_deg``; otherwise
   ``ds`` is halved and the step retried. Below ``ds_min`` the run stops with
   :attr:`Status.STEP_TOO_SMALL` and a message saying where, what was tried and the residual.
5. **Step size**: ``ds *= clip(min(target_iterations / work, max_angle / (2 angle)), 1/2, 2)``, with
   ``work`` the corrector's Newton iterations plus half its chord iterations (a chord iteration
   is one residual and two triangular solves, about half a Newton iteration's cost),
   kept in ``[ds_min, ds_max]`` and, optionally, so that the predicted change of ``p/p_ref`` is
   at most ``max_parameter_step``.

A **fold** (turning point in ``p``) is where the ``p``-component of the tangent changes sign; it
is located by Illinois regula falsi on that component along the arc and inserted into the
branch as a converged point of kind :attr:`PointKind.FOLD`. The run stops exactly at ``p_end``
(the last point is solved at ``p = p_end``), at ``max_points``, or when the branch turns back
past ``p0``. Only converged points are ever stored: no silent gaps.
"""

from __future__ import annotations

import enum
import math
import sys
import time
import warnings
from dataclasses import dataclass
from typing import Callable, NamedTuple

import numpy as np
import scipy.linalg

from ..newton import newton

__all__ = ["PseudoArclength", "continuation", "sweep_method", "Branch", "Status", "PointKind"]


class Status(enum.IntEnum):
    """Overall outcome of a continuation run (see :data:`MESSAGES`)."""

    SUCCESS = 0  # reached p_end
    MAX_POINTS = 1  # max_points reached before p_end
    STEP_TOO_SMALL = 2  # no acceptable step with ds >= ds_min
    START_FAILED = 3  # Newton at p0 did not converge
    TURNED_BACK = 4  # the branch went back past p0
    STOPPED = 5  # the callback asked to stop


MESSAGES = {
    Status.SUCCESS: "reached the end of the parameter range",
    Status.MAX_POINTS: "stopped at max_points before the end of the range; raise max_points or ds_max",
    Status.STEP_TOO_SMALL: "no acceptable continuation step above ds_min; try more harmonics, a smaller "
    "ds_min, more corrector iterations or a smoother model",
    Status.START_FAILED: "the starting point did not converge; give a better z0",
    Status.TURNED_BACK: "the branch turned back past the start of the range (an isola or a branch that "
    "does not reach p_end)",
    Status.STOPPED: "stopped by the callback",
}


class PointKind(enum.IntEnum):
    """What a stored branch point is."""

    START = 0
    REGULAR = 1
    FOLD = 2  # located turning point (p-component of the tangent ~ 0)
    END = 3  # solved exactly at p_end


@dataclass(frozen=True)
class PseudoArclength:
    """Options of pseudo-arclength continuation (all step sizes in scaled units).

    **Arguments:**

    - `ds`: initial arclength step in ``(z, p/p_ref)`` [-]; `ds_min`, `ds_max`: its bounds.
    - `max_corrector_iterations`: Newton iterations allowed per step.
    - `target_iterations`: the Newton-equivalent corrector iterations the step-size control
      aims at (a chord iteration counts one half).
    - `max_angle_deg`: largest angle between successive tangents [deg].
    - `parameter_scale`: ``p_ref`` [units of p]; ``None`` = ``max(|p0|, |p_end|)``.
    - `growth`: largest factor by which ``ds`` grows after a step (it shrinks by at most 2).
    - `max_parameter_step`: largest predicted change of ``p/p_ref`` per step [-] (``None``: no
      limit) -- the resolution in ``p`` where the branch is flat while ``ds_max`` is sized for
      the unknowns.
    - `jit_step`: run each corrector (Newton iterations, line search, tangent) as ONE compiled
      JAX function (``lax.while_loop``) instead of a Python loop, and runs of regular steps (up
      to ``SEGMENT_POINTS`` per call, with the same predictor, acceptance tests and step-size
      control) inside it; any other step (refused, failed, a fold, the end of the range) goes
      back to the Python loop. Needs residual functions that
      JAX can trace in ``(z, p, *args)`` (e.g. :func:`hbgear.engine.hb.residual_functions`,
      the gear pair in ``args``, or :meth:`hbgear.engine.hb.HarmonicBalance.residual_and_jacobians`
      with the system closed over); otherwise the run falls back to the Python corrector with
      a warning. Same algorithm, same points to rounding (LU by XLA instead of scipy); it
      removes the per-evaluation and per-step dispatch and conversion overhead, which dominates
      small and mid-size problems. Costs one compilation per set of residual functions (1-5 s;
      kept in the disk cache, and ``p_ref`` is an argument, so a new range does not recompile).
    - `chord`: with `jit_step`, a modified (chord) Newton corrector: the iterations reuse the LU
      of the bordered Jacobian factored for the tangent at the last converged point (one
      residual evaluation and two triangular solves per iteration, no Jacobian), and the
      Jacobian is evaluated once per point, at the converged point, for its tangent. If the
      chord iteration does not halve ``max |R|`` at every step, the full Newton corrector runs
      from the predictor. Same acceptance test (``max |R| <= tolerance``), so the points agree
      with the Newton corrector's to the tolerance; the iteration counts differ (the step-size
      control counts a chord iteration as half a Newton iteration, by cost, so that the chord
      mode's slower, linear convergence does not shrink the steps). Without `jit_step` it has
      no effect.
    """

    ds: float = 1e-2
    ds_min: float = 1e-7
    ds_max: float = 5e-2
    max_corrector_iterations: int = 10
    target_iterations: int = 4
    max_angle_deg: float = 10.0
    parameter_scale: float | None = None
    growth: float = 2.0
    max_parameter_step: float | None = None
    jit_step: bool = False
    chord: bool = False

    def __post_init__(self):
        if not (0 < self.ds_min <= self.ds <= self.ds_max and math.isfinite(self.ds_max)):
            raise ValueError(f"need 0 < ds_min <= ds <= ds_max < inf, got {self.ds_min}, {self.ds}, {self.ds_max}")
        if not 1 <= self.target_iterations <= self.max_corrector_iterations:
            raise ValueError("need 1 <= target_iterations <= max_corrector_iterations")
        if not 0 < self.max_angle_deg < 90:
            raise ValueError(f"max_angle_deg must be in (0, 90), got {self.max_angle_deg}")
        if self.parameter_scale is not None and not (self.parameter_scale > 0 and math.isfinite(self.parameter_scale)):
            raise ValueError(f"parameter_scale must be a positive finite number, got {self.parameter_scale}")
        if not self.growth > 1:
            raise ValueError("growth must be > 1")
        if self.max_parameter_step is not None and not self.max_parameter_step > 0:
            raise ValueError(f"max_parameter_step must be > 0, got {self.max_parameter_step}")


def sweep_method(p_start, p_stop, step=None) -> PseudoArclength:
    """Continuation options for a sweep of the parameter from `p_start` to `p_stop`.

    ``p_ref`` = the larger end value; the unknowns are scaled (the gear pair: in static
    deflections), so a step moves them by at most 0.25 (``ds_max``) and the parameter by at most
    1/100 of the range (``max_parameter_step``; at least ~100 points on a flat curve); tangents
    turn by at most 5 deg per step. First step: `step` (same unit as ``p``; the gear pair's
    ``[sweep] step_rpm``) or 1/4 of the largest parameter step. Compiled chord corrector.
    """
    scale = max(abs(p_start), abs(p_stop))
    dp_max = abs(p_stop - p_start) / scale / 100
    ds = dp_max / 4 if step is None else step / scale
    dp_max = max(dp_max, ds)
    return PseudoArclength(
        ds=ds, ds_min=min(1e-7, ds / 10), ds_max=max(0.25, ds), max_angle_deg=5.0,
        parameter_scale=scale, max_parameter_step=dp_max, jit_step=True, chord=True,
    )


@dataclass(frozen=True)
class Branch:
    """A continued branch: an immutable struct of arrays, points in path order.

    **Fields:** `p` (n,) parameter; `z` (n, size) unknowns; `kind` (n,) :class:`PointKind`;
    `iterations` (n,) corrector iterations; `residual` (n,) ``max |R|``; `tangent_p` (n,)
    ``p``-component of the unit tangent in scaled units (its sign is the direction of travel in
    ``p``; it changes sign at folds); `ds` (n,) arclength step that reached the point;
    `status` :class:`Status`; `message`; `parameter_scale` ``p_ref``; `rejected` steps refused;
    `start_seconds` the wall time of the start (with `jit_step`: the compilation of the corrector
    on its first use, then Newton at ``p0`` and the first tangent).
    """

    p: np.ndarray
    z: np.ndarray
    kind: np.ndarray
    iterations: np.ndarray
    residual: np.ndarray
    tangent_p: np.ndarray
    ds: np.ndarray
    status: Status
    message: str
    parameter_scale: float
    rejected: int = 0
    start_seconds: float = 0.0

    def __post_init__(self):
        for name in ("p", "z", "kind", "iterations", "residual", "tangent_p", "ds"):
            value = np.array(getattr(self, name))
            value.flags.writeable = False
            object.__setattr__(self, name, value)

    def __len__(self) -> int:
        return len(self.p)

    @property
    def success(self) -> bool:
        return self.status == Status.SUCCESS

    @property
    def folds(self) -> np.ndarray:
        """Indices of the located fold points."""
        return np.flatnonzero(self.kind == PointKind.FOLD)

    @property
    def fold_p(self) -> np.ndarray:
        return self.p[self.folds]


class _Point(NamedTuple):
    y: np.ndarray  # (z, p/p_ref)
    r_norm: float
    tangent: np.ndarray  # unit tangent at y, oriented along the `previous` given to the corrector
    iterations: int  # Newton + chord iterations (stored with the point)
    work: float  # Newton-equivalent iterations, for the step-size control: Newton + chord / 2


#: Cost of a chord iteration (one residual, two triangular solves) in Newton iterations (one
#: (R, R_z, R_p) evaluation and one LU): the residual is about half an evaluation's cost.
CHORD_ITERATION_WORK = 0.5


class _Failure(NamedTuple):
    reason: str
    r_norm: float
    iterations: int


_FAILURES = {1: "non-finite residual", 2: "singular bordered Jacobian"}


def _grown_step(ds, work, angle_deg, ds_min, ds_max, max_angle_deg, growth, target_iterations, xp=np):
    """``ds`` after an accepted step (module doc, item 5): ``ds * clip(min(target / work,
    max_angle / (2 angle)), 1/2, growth)`` kept in ``[ds_min, ds_max]``; numpy or JAX (the
    compiled segments run the same rule)."""
    gain = target_iterations / xp.maximum(work, 1.0)
    gain = xp.where(angle_deg > 0, xp.minimum(gain, max_angle_deg / (2 * xp.maximum(angle_deg, 1e-300))), gain)
    return xp.minimum(ds_max, xp.maximum(ds_min, ds * xp.minimum(growth, xp.maximum(0.5, gain))))


def _limited_step(ds, tangent_p, ds_min, max_parameter_step, xp=np):
    """``ds`` cut so that the predicted change of ``p / p_ref`` is at most `max_parameter_step`
    (``inf``: no limit), not below `ds_min`."""
    slope = xp.abs(tangent_p)
    return xp.where(slope * ds > max_parameter_step,
                    xp.maximum(ds_min, max_parameter_step / xp.maximum(slope, 1e-300)), ds)


def _unit(v):
    return v / np.linalg.norm(v)


def _tangent(bordered, previous):
    """Unit null vector of ``J = bordered[:-1]`` with ``t . previous > 0``; ``bordered`` is the
    ``(m+1, m+1)`` buffer holding ``J``, its last row is overwritten with ``previous``."""
    n = bordered.shape[0] - 1
    bordered[n] = previous
    b = np.zeros(n + 1)
    b[-1] = 1.0
    try:
        t = scipy.linalg.solve(bordered, b, check_finite=False)
    except (np.linalg.LinAlgError, ValueError):
        t = np.full(n + 1, np.nan)
    if not np.all(np.isfinite(t)):  # degenerate border: fall back to the SVD null vector
        t = np.linalg.svd(bordered[:n])[2][-1]
    t = _unit(t)
    return t if t @ previous >= 0 else -t


def _python_corrector(residual_and_jacobians, residual, scale, size):
    """``correct(y_pred, row, target, previous, max_iter, tolerance) -> _Point | _Failure``:
    Newton on ``R(y) = 0``, ``row . y = target`` with a backtracking line search on ``max |R|``
    (residual only, and only when the full step does not decrease it), then the tangent at the
    converged point from the Jacobian already evaluated there."""

    def evaluate(y):
        """``(R, A)``: ``A`` the bordered matrix ``[[R_z, R_p p_ref], [.]]``, last row unset."""
        r, jz, jp = residual_and_jacobians(y[:-1], float(y[-1] * scale))
        a = np.empty((size + 1, size + 1), order="F")
        a[:size, :size] = np.asarray(jz, dtype=float)
        a[:size, size] = scale * np.asarray(jp, dtype=float).reshape(-1)
        return np.asarray(r, dtype=float), a

    def norm_of(y):
        return float(np.max(np.abs(np.asarray(residual(y[:-1], float(y[-1] * scale))))))

    def correct(y_pred, row, target, previous, max_iter, tolerance):
        y = y_pred.copy()
        r, a = evaluate(y)
        norm = float(np.max(np.abs(r)))
        b = np.empty(size + 1)
        for it in range(max_iter + 1):
            if not np.isfinite(norm):
                return _Failure(_FAILURES[1], norm, it)
            if norm <= tolerance and abs(row @ y - target) <= 1e-12 * (1 + abs(target)):
                return _Point(y, norm, _tangent(a, previous), it, it)
            if it == max_iter:
                break
            a[size] = row
            b[:size] = -r
            b[size] = -(row @ y - target)
            try:  # `a` is this iterate's own buffer: factor it in place
                step = scipy.linalg.lu_solve(scipy.linalg.lu_factor(a, overwrite_a=True, check_finite=False), b,
                                             check_finite=False)
            except (np.linalg.LinAlgError, ValueError):
                return _Failure(_FAILURES[2], norm, it)
            if not np.all(np.isfinite(step)):
                return _Failure(_FAILURES[2], norm, it)
            trial = y + step
            r_trial, a_trial = evaluate(trial)
            trial_norm = float(np.max(np.abs(r_trial)))
            if not (np.isfinite(trial_norm) and trial_norm < (1 - 1e-4) * norm):
                alpha = 1.0  # backtracking on max|R| (the linear constraint stays satisfied)
                while alpha > 1 / 8:
                    alpha *= 0.5
                    trial = y + alpha * step
                    trial_norm = norm_of(trial)
                    if np.isfinite(trial_norm) and trial_norm < (1 - 1e-4 * alpha) * norm:
                        break
                r_trial, a_trial = evaluate(trial)
                trial_norm = float(np.max(np.abs(r_trial)))
            y, r, a, norm = trial, r_trial, a_trial, trial_norm
        return _Failure(f"not converged in {max_iter} corrector iterations", norm, max_iter)

    return correct


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
        if status == 3:
            return _Failure(f"not converged in {max_iter} corrector iterations", norm, int(max_iter))
        return _Failure(_FAILURES[status], norm, newton_it + chord_it)

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


def _angle_deg(a, b):
    return math.degrees(math.acos(min(1.0, max(-1.0, float(a @ b)))))


def continuation(
    residual_and_jacobians: Callable,
    residual: Callable,
    z0,
    p0: float,
    p_end: float,
    method: PseudoArclength = PseudoArclength(),
    *,
    max_points: int = 1000,
    tolerance: float = 1e-9,
    callback: Callable | None = None,
    progress: bool | None = None,
    start_iterations: int = 50,
    args: tuple = (),
) -> Branch:
    r"""Follow the branch of ``R(z; p) = 0`` from ``(z0, p0)`` towards ``p_end``.

    **Arguments:**

    - `residual_and_jacobians`: ``(z, p) -> (R, dR/dz, dR/dp)``, shapes ``(m,)``, ``(m, m)``, ``(m,)``.
    - `residual`: ``(z, p) -> R`` (line search).
    - `z0`: starting guess at `p0` (corrected by Newton at fixed ``p0`` first); `p_end`: where to
      stop (either side of `p0`).
    - `method`: :class:`PseudoArclength` options.
    - `max_points`: stored points at most (start, folds and end included); `tolerance`: on
      ``max |R|``.
    - `callback(p, z)`: called for every stored point in path order; returning ``True`` stops
      the run (:attr:`Status.STOPPED`).
    - `progress`: a tqdm bar on stderr; ``None`` = only when stderr is a terminal.
    - `start_iterations`: Newton iterations for the starting point.
    - `args`: extra arguments (a tuple of JAX pytrees) passed to both functions after ``(z,
      p)``. With `jit_step` they are arguments of the compiled corrector, not constants in it:
      new values (a new model's parameters) reuse the compiled program and its disk cache.

    **Returns:** a :class:`Branch`; failures are its `status` and `message`, never exceptions.
    """
    if p_end == p0:
        raise ValueError("p_end must differ from p0")
    if max_points < 2:
        raise ValueError("max_points must be >= 2")
    m = method
    scale = float(m.parameter_scale or max(abs(p0), abs(p_end)))
    direction = 1.0 if p_end > p0 else -1.0
    z0 = np.asarray(z0, dtype=float)
    size = z0.size
    max_parameter_step = math.inf if m.max_parameter_step is None else m.max_parameter_step

    args = tuple(args)
    compiled_functions = (residual_and_jacobians, residual)
    if args:
        def residual_and_jacobians(z, p, _f=residual_and_jacobians):
            return _f(z, p, *args)

        def residual(z, p, _f=residual):
            return _f(z, p, *args)

    python_correct = _python_corrector(residual_and_jacobians, residual, scale, size)
    corrector = [python_correct]
    key = compiled_functions + (size,)
    if m.jit_step:
        if key not in _JIT_CACHE:  # the same callables again (e.g. repeated runs): no new trace
            if len(_JIT_CACHE) >= 8:
                _JIT_CACHE.pop(next(iter(_JIT_CACHE)))
            _JIT_CACHE[key] = _jit_corrector(*compiled_functions, size)
        controls = (m.ds_min, m.ds_max, m.max_angle_deg, m.growth, m.target_iterations, max_parameter_step,
                    p_end / scale, direction, p0 / scale)
        corrector[0] = _Compiled(_JIT_CACHE[key], m.chord, scale, controls, args)

    def correct(y_pred, row, target, max_iter, previous, tol=tolerance):
        """Newton on ``R(y) = 0``, ``row . y = target``; a _Point (with the tangent oriented
        along `previous`) or a _Failure."""
        if corrector[0] is python_correct:
            return python_correct(y_pred, row, target, previous, max_iter, tol)
        try:
            return corrector[0](y_pred, row, target, previous, max_iter, tol)
        except Exception as error:  # not traceable by JAX: the Python corrector, same algorithm
            fall_back(error)
            return python_correct(y_pred, row, target, previous, max_iter, tol)

    def fall_back(error):
        warnings.warn(f"jit_step: the residual functions could not be compiled ({type(error).__name__}: "
                      f"{str(error).splitlines()[0] if str(error) else ''}); using the Python corrector",
                      RuntimeWarning, stacklevel=4)
        corrector[0] = python_correct
        _JIT_CACHE.pop(key, None)

    # -- storage -----------------------------------------------------------------------------
    rows = {k: [] for k in ("p", "z", "kind", "iterations", "residual", "tangent_p", "ds")}
    stopped = [False]

    def store(y, kind, iterations, r_norm, t, ds, p=None):
        rows["p"].append(y[-1] * scale if p is None else p)
        rows["z"].append(y[:-1].copy())
        rows["kind"].append(int(kind))
        rows["iterations"].append(iterations)
        rows["residual"].append(r_norm)
        rows["tangent_p"].append(float(t[-1]))
        rows["ds"].append(ds)
        if callback is not None and callback(float(rows["p"][-1]), y[:-1].copy()):
            stopped[0] = True

    rejected = 0
    start_seconds = 0.0
    clock_start = time.perf_counter()

    def finish(status, detail=""):
        message = MESSAGES[status] if not detail else f"{detail}. {MESSAGES[status]}"
        empty = np.zeros((0, size))
        return Branch(
            p=np.asarray(rows["p"], dtype=float),
            z=np.asarray(rows["z"], dtype=float) if rows["z"] else empty,
            kind=np.asarray(rows["kind"], dtype=np.int8),
            iterations=np.asarray(rows["iterations"], dtype=int),
            residual=np.asarray(rows["residual"], dtype=float),
            tangent_p=np.asarray(rows["tangent_p"], dtype=float),
            ds=np.asarray(rows["ds"], dtype=float),
            status=status,
            message=message,
            parameter_scale=scale,
            rejected=rejected,
            start_seconds=start_seconds,
        )

    # -- start -------------------------------------------------------------------------------
    seed = np.zeros(size + 1)
    seed[-1] = direction
    fixed_p = np.abs(seed)
    first = None
    if isinstance(corrector[0], _Compiled):
        # Newton at fixed p0 and the tangent there in one call of the compiled corrector (no
        # separately compiled residual functions needed); on failure the Python Newton below
        y_guess = np.append(z0, p0 / scale)
        try:
            first = corrector[0](y_guess, fixed_p, p0 / scale, seed, start_iterations, tolerance)
        except Exception:  # noqa: BLE001 -- e.g. a closure that fills a cache on its first call,
            residual(z0, float(p0))  # which must be eager: call it once, then trace again
            first = correct(y_guess, fixed_p, p0 / scale, start_iterations, seed)  # or fall back
        first = first if isinstance(first, _Point) else None
    if first is None:
        start = newton(
            lambda z: residual_and_jacobians(z, float(p0))[:2],
            lambda z: residual(z, float(p0)),
            z0,
            tolerance=tolerance,
            max_iterations=start_iterations,
        )
        if not start.converged:
            return finish(
                Status.START_FAILED,
                f"Newton at p = {p0:.9g} reached max|R| = {start.residual_norm:.3e} > tolerance {tolerance:.1e} "
                f"after {start.iterations} iterations",
            )
        y = np.append(np.asarray(start.z, dtype=float), p0 / scale)
        first = correct(y, fixed_p, y[-1], 0, seed, tol=math.inf)  # R, J at the start: the tangent
        if not isinstance(first, _Point):
            return finish(Status.START_FAILED, f"the Jacobian at p = {p0:.9g} could not be evaluated: {first.reason}")
        first = first._replace(iterations=start.iterations)
    y = first.y
    t = first.tangent
    if t[-1] * direction <= 0:  # started on a fold or against the range: push towards p_end
        t = -t if t[-1] * direction < 0 else t
    store(y, PointKind.START, first.iterations, first.r_norm, t, 0.0, p=float(p0))
    start_seconds = time.perf_counter() - clock_start

    bar = _progress_bar(progress, p0, p_end)
    ds = m.ds
    end_scaled = p_end / scale
    detail = ""
    status = None
    try:
        while status is None:
            if stopped[0]:
                status = Status.STOPPED
                break
            if len(rows["p"]) >= max_points:
                status = Status.MAX_POINTS
                detail = f"{max_points} points stored, last at p = {y[-1] * scale:.9g}"
                break
            tried = []
            ds = float(_limited_step(ds, t[-1], m.ds_min, max_parameter_step))
            pending = None
            if isinstance(corrector[0], _Compiled):  # regular steps in one compiled call
                try:
                    points, pending, (y, t, ds) = corrector[0].segment(
                        y, t, ds, m.max_corrector_iterations, tolerance, max_points - len(rows["p"]))
                except Exception as error:  # not traceable by JAX: the Python corrector from here
                    fall_back(error)
                    points = []
                for y_new, t_new, r_norm, iterations, ds_used in points:
                    store(y_new, PointKind.REGULAR, iterations, r_norm, t_new, ds_used)
                    if stopped[0]:
                        break
                if points and bar is not None:
                    _advance_bar(bar, y, scale, p0, p_end, len(rows["p"]), ds)
                if stopped[0] or pending is None:
                    continue  # stopped, at max_points, or the next segment
            while True:
                y_pred = y + ds * t
                if pending is not None:  # the segment's last corrector run, from this predictor
                    result, pending = pending, None
                else:
                    result = correct(y_pred, t, t @ y_pred, m.max_corrector_iterations, t)
                if isinstance(result, _Point):
                    t_new = result.tangent
                    angle = _angle_deg(t_new, t)
                    offset = float(np.linalg.norm(result.y - y_pred))
                    if offset > ds and ds > m.ds_min:
                        result = _Failure(f"corrector moved {offset:.2e} > ds off the predictor", result.r_norm, result.iterations)
                    elif angle > m.max_angle_deg and ds > m.ds_min:
                        result = _Failure(f"tangent turned {angle:.1f} deg > {m.max_angle_deg:g}", result.r_norm, result.iterations)
                if isinstance(result, _Point):
                    break
                tried.append((ds, f"ds={ds:.3g}: {result.reason} (max|R|={result.r_norm:.2e})"))
                rejected += 1
                if ds <= m.ds_min:
                    status = Status.STEP_TOO_SMALL
                    detail = (
                        f"stuck at p = {y[-1] * scale:.9g} (tangent p-component {t[-1]:+.3g}, "
                        f"max|R| = {float(rows['residual'][-1]):.2e} there): {len(tried)} step sizes tried "
                        f"from ds = {float(tried[0][0]):.3g} down to ds_min = {m.ds_min:.3g}, the last: "
                        + "; ".join(text for _, text in tried[-3:])
                    )
                    break
                ds = max(m.ds_min, 0.5 * ds)
            if status is not None:
                break
            y_new, point = result.y, result

            # fold: the p-component of the tangent changed sign
            if t_new[-1] * t[-1] < 0:
                fold = _locate_fold(correct, y, t, y_new, float(t_new[-1]), m.max_corrector_iterations)
                if fold is not None and (fold.y[-1] - end_scaled) * direction < 0:
                    t_fold = fold.tangent
                    store(fold.y, PointKind.FOLD, fold.iterations, fold.r_norm, t_fold, float(t @ (fold.y - y)))
                    if len(rows["p"]) >= max_points:
                        y, t = fold.y, t_fold
                        continue

            # end of the range: crossed p_end -> solve exactly there
            if (y_new[-1] - end_scaled) * direction >= 0:
                frac = (end_scaled - y[-1]) / (y_new[-1] - y[-1])
                guess = y + frac * (y_new - y)
                row = np.zeros(size + 1)
                row[-1] = 1.0
                last = correct(guess, row, end_scaled, m.max_corrector_iterations, t)
                if isinstance(last, _Point):
                    t_last = last.tangent
                    store(last.y, PointKind.END, last.iterations, last.r_norm, t_last, float(np.linalg.norm(last.y - y)), p=float(p_end))
                    status = Status.SUCCESS
                    y = last.y
                    break
                ds = max(m.ds_min, 0.5 * ds)  # come closer first
                if ds > m.ds_min:
                    continue
                status = Status.STEP_TOO_SMALL
                detail = f"could not solve at p_end = {p_end:.9g}: {last.reason} (max|R|={last.r_norm:.2e})"
                break
            # went back past the start
            if (y_new[-1] - p0 / scale) * direction < 0 and (y[-1] - p0 / scale) * direction >= 0 and len(rows["p"]) > 1:
                store(y_new, PointKind.REGULAR, point.iterations, point.r_norm, t_new, ds)
                status = Status.TURNED_BACK
                detail = f"at p = {y_new[-1] * scale:.9g}"
                break

            store(y_new, PointKind.REGULAR, point.iterations, point.r_norm, t_new, ds)
            # `angle`: between t and t_new, from the acceptance test of this step
            ds = float(_grown_step(ds, point.work, angle, m.ds_min, m.ds_max, m.max_angle_deg, m.growth,
                                   m.target_iterations))
            y, t = y_new, t_new
            if bar is not None:
                _advance_bar(bar, y, scale, p0, p_end, len(rows["p"]), ds)
    finally:
        if bar is not None:
            bar.close()
    return finish(status, detail)


def _advance_bar(bar, y, scale, p0, p_end, points, ds):
    bar.n = round(100 * min(1.0, max(0.0, (y[-1] * scale - p0) / (p_end - p0))), 1)
    bar.set_postfix(p=f"{y[-1] * scale:.6g}", points=points, ds=f"{ds:.2g}", refresh=False)
    bar.refresh()


class IllinoisBracket(NamedTuple):
    """A sign-changing bracket ``f(a) f(b) <= 0`` narrowed by Illinois regula falsi.

    :meth:`point` is the next evaluation point; :meth:`narrowed` keeps the sub-bracket that
    still changes sign and halves the stale end's value when the same end is kept twice.
    """

    a: float
    fa: float
    b: float
    fb: float
    side: int = 0

    def point(self) -> float:
        return (self.a * self.fb - self.b * self.fa) / (self.fb - self.fa)

    def narrowed(self, c: float, fc: float) -> IllinoisBracket:
        if fc * self.fa > 0:
            return IllinoisBracket(c, fc, self.b, self.fb * 0.5 if self.side == -1 else self.fb, -1)
        return IllinoisBracket(self.a, self.fa * 0.5 if self.side == 1 else self.fa, c, fc, 1)


def illinois(g, a, ga, b, gb, best, rel_tol, max_steps):
    """Illinois regula falsi on ``g(x) -> (value, data)`` from the bracket ``(a, ga), (b, gb)``
    until it is below `rel_tol` (relative to ``max(|a|, |b|)``) or a value is 0.

    **Returns:** the best ``(x, data, value)`` seen (`best`: the better end's, same form) and
    the last :class:`IllinoisBracket`.
    """
    bracket = IllinoisBracket(a, ga, b, gb)
    for _ in range(max_steps):
        if abs(bracket.b - bracket.a) <= rel_tol * max(abs(bracket.a), abs(bracket.b)) or best[2] == 0:
            break
        c = bracket.point()
        gc, data = g(c)
        if abs(gc) <= abs(best[2]):
            best = (c, data, gc)
        bracket = bracket.narrowed(c, gc)
    return best, bracket


def _locate_fold(correct, y0, t0, y1, g1, max_iter, max_steps=40):
    """The turning point between two converged points: zero of the tangent's p-component along
    the arc, parametrised by ``s = t0 . (y - y0)``, by Illinois regula falsi."""
    h = float(t0 @ (y1 - y0))

    def at(s):
        point = correct(y0 + s * t0, t0, float(t0 @ y0) + s, max_iter, t0)
        if not isinstance(point, _Point):
            return None, None
        return point, point.tangent[-1]

    bracket = IllinoisBracket(0.0, float(t0[-1]), h, g1)
    best = None
    for _ in range(max_steps):
        s = bracket.point()
        point, g = at(s)
        if point is None:
            return best
        best = point
        if abs(g) < 1e-12 or abs(bracket.b - bracket.a) < 1e-13 * max(abs(h), 1e-300):
            return point
        bracket = bracket.narrowed(s, g)
    return best


def _progress_bar(progress, p0, p_end):
    if progress is False:
        return None
    if progress is None and not (hasattr(sys.stderr, "isatty") and sys.stderr.isatty()):
        return None
    try:
        from tqdm.auto import tqdm
    except ImportError:  # pragma: no cover
        return None
    return tqdm(total=100, desc=f"continuation {p0:.6g} -> {p_end:.6g}", unit="%", leave=False, file=sys.stderr,
                bar_format="{desc}: {percentage:3.0f}%|{bar}| [{elapsed}<{remaining}{postfix}]")
