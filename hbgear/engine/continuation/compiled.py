"""The compiled corrector: the continuation step as one JAX program (``jit_step``).

It is the compiled twin of :mod:`.corrector` (the engine's Newton on the bordered system
``R(y) = 0``, ``row . y = target``): the same full step evaluated with its Jacobian, the same
residual-only halving of a step that does not decrease ``max |R|`` down to
:data:`~.corrector.LINE_SEARCH_MIN_STEP`, the same convergence test and the same
:class:`~hbgear.engine.newton.NewtonStatus` values, with XLA's LU instead of scipy's. Added
here: the *chord* mode (the LU of the last converged point reused, a rank-one update for the
new border row) and *segments*: up to :data:`SEGMENT_POINTS` regular continuation steps
(predictor, corrector, acceptance, step-size control of :mod:`.driver`) in one call.

One corrector loop turn = one evaluation at a candidate; ``mode`` says what the candidate is
(:data:`PREDICTOR`, :data:`NEWTON`, :data:`BACKTRACKED`, :data:`CHORD`). Each callable is traced
once, whatever the number of iterations or steps; the parameter scale ``p_ref`` and the
residual's extra ``args`` (the gear pair) are arguments of the program, so a new range or a new
pair of the same structure does not recompile.

The Jacobian ``R_z`` is a matrix, or an object with ``bordered_factor(column, row)`` (a
:class:`~hbgear.engine.condensed.PortJacobian`, a :class:`~hbgear.engine.structured.KrylovJacobian`:
a factorisation with ``solve(b)``, and ``dense()``); then every LU of a bordered matrix below is
that factorisation (:func:`_factor_bordered`, :func:`_solve_bordered`: Woodbury on the ports, or
GMRES with the bordered band preconditioner), the same algorithm on cheaper linear algebra.

The loop states are NamedTuples (JAX pytrees), their fields in alphabetical order. XLA copies a
loop variable that a ``lax.cond`` branch passes through while the other makes a new one, so the
large arrays are kept out of such branches: a corrector run is a loop of chord turns (no
Jacobian in its state) and then a loop of Newton turns, each of which evaluates ``J`` at its
candidate and stores it outside its branches; the tangent's LU is made in the one conditional
that otherwise passes the previous LU through.
"""

from __future__ import annotations

from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..caching import BoundedCache
from ..condensed import lu_factor, lu_solve
from ..newton import SUFFICIENT_DECREASE, NewtonStatus
from ..persistent import persistent
from ..typed_jit import node_types, typed_jit
from .corrector import CHORD_ITERATION_WORK, LINE_SEARCH_MIN_STEP, _failure, _Point
from .steps import _grown_step, _limited_step

#: Regular steps one call of the compiled corrector may take in a row (:meth:`_Compiled.segment`).
SEGMENT_POINTS = 32

#: ``mode`` of a corrector loop turn: what the candidate it evaluates is. The predictor (or the
#: chord's converged point) is taken as it is; a full Newton step is taken if it decreases
#: ``max |R|``, else a residual-only backtracking gives the next candidate, taken as it is.
PREDICTOR, NEWTON, BACKTRACKED, CHORD = 0, 1, 2, 3
#: ``mode`` of the chord loop's first turn: it evaluates ``R`` at the predictor and takes no step
#: (one residual in the program for the chord loop's start and its steps: each copy of the
#: residual is compiled on its own).
CHORD_START = 4

#: ``status`` while the corrector runs (then a NewtonStatus value).
RUNNING = -1

_CONVERGED, _NONFINITE = int(NewtonStatus.CONVERGED), int(NewtonStatus.NONFINITE)
_SINGULAR, _MAX_ITERATIONS = int(NewtonStatus.SINGULAR_JACOBIAN), int(NewtonStatus.MAX_ITERATIONS)


def _running(condition, count):
    """``condition & (count >= 0)`` for a ``lax.while_loop`` whose `count` never goes negative.

    The second, always true, term makes the loop condition read two loop variables. XLA's
    while-loop passes look for an induction variable whenever the condition reads only one;
    they then extract and clone everything that computes it in the loop body, here the whole
    corrector, several times per compilation (a third of the HLO-pass time of the gear pair's
    program). With two variables the search stops at the condition.
    """
    return condition & (count >= 0)


class _Factor(NamedTuple):
    """The LU of ``A = [J; previous]`` at the last converged point (for the chord mode): `lu`
    and its row permutation `perm` (:func:`~hbgear.engine.condensed.lu_factor`); with a
    structured Jacobian `lu` is its factorisation and `perm` unused."""

    lu: Any
    perm: Any
    v: Any  # A^-1 e: the unnormalised tangent
    previous: Any  # the border row A was factored with
    usable: Any  # bool: a factorisation the chord mode may use


class _Iterate(NamedTuple):
    """State of the corrector loop (one turn per evaluation)."""

    cand: Any  # the candidate the next turn evaluates
    chord_it: Any  # chord iterations taken
    it: Any  # Newton iterations taken (in the chord mode: chord steps so far)
    jac: Any  # [R_z, p_ref R_p] at y
    mode: Any  # what `cand` is: PREDICTOR, NEWTON, BACKTRACKED or CHORD
    norm: Any  # max|R| at y (inf: no comparison for the next candidate)
    r: Any  # R at y (chord mode)
    status: Any  # RUNNING, then a NewtonStatus value
    step: Any  # the last Newton step (for the line search)
    y: Any  # the current iterate


class _Segment(NamedTuple):
    """State of the segment loop (one turn per corrector run)."""

    done: Any
    ds: Any  # the step size of the next step
    factor: _Factor  # the chord LU
    info: Any  # (SEGMENT_POINTS, 3): max|R|, iterations, ds of each regular point
    k: Any  # regular steps taken
    pending: Any  # the last corrector run when it was not a regular step (see `advance`)
    previous: Any  # tangent orientation for the next corrector run
    row: Any  # border row of the next corrector run
    t: Any  # unit tangent at y
    t_out: Any  # (SEGMENT_POINTS, m): tangents of the regular points
    target: Any  # border target of the next corrector run
    y: Any  # the last regular point
    y_out: Any  # (SEGMENT_POINTS, m): the regular points
    y_pred: Any  # predictor of the next corrector run


class SegmentControls(NamedTuple):
    """The step-size controls of a segment (scaled; `p_end`, `p_start` in ``p / p_ref``)."""

    ds_min: Any
    ds_max: Any
    max_angle_deg: Any
    growth: Any
    target_iterations: Any
    max_parameter_step: Any  # inf: no limit
    p_end: Any
    direction: Any  # sign of p_end - p_start
    p_start: Any


class _Equations(NamedTuple):
    """One corrector run's bordered equations ``R(y) = 0``, ``row . y = target`` (traced values
    and the callables, fixed while the program is traced)."""

    residual_and_jacobians: Callable
    residual: Callable
    size: int
    scale: Any
    args: tuple
    y_pred: Any
    row: Any
    target: Any
    max_iter: Any
    tolerance: Any


class _Chord(NamedTuple):
    """The chord step's pieces: ``B = A + e d^T``, ``d = row - previous_f``."""

    lu: Any
    perm: Any
    v: Any
    d: Any
    denominator: Any  # 1 + d . v


def _no_factor(size, previous, lu=None) -> _Factor:
    """An unusable chord factorisation, with `previous`: zeros of the dense LU's shape, or `lu`
    (zeros of a structured factorisation's). Numpy zeros put on the device, not ``jnp.zeros``,
    which compiles a program of its own per shape."""
    dense = lu is None
    lu = np.zeros((size + 1, size + 1)) if dense else lu
    perm = np.zeros(size + 1 if dense else 1, np.int32)  # the structured factorisation has no permutation
    return _Factor(*jax.device_put((lu, perm, np.zeros(size + 1))), previous, jax.device_put(np.asarray(False)))


# ------------------------------------------------------------------------------ linear algebra
def _structured(jz) -> bool:
    return hasattr(jz, "bordered_factor")


def _factor_bordered(jac, row):
    """The factorisation of ``[jac; row]``: ``(lu, perm)`` of the matrix, or with a structured
    ``jac = (R_z, column)`` its ``bordered_factor`` (and a placeholder permutation). The
    permutation is made once here, not at every solve (``jax.scipy.linalg.lu_solve`` would turn
    the pivots into it at each of the ~4 solves a point)."""
    if isinstance(jac, tuple):
        return jac[0].bordered_factor(jac[1], row), jnp.zeros(1, np.int32)
    return lu_factor(jnp.concatenate([jac, row[None]], axis=0))


def _solve_bordered(lu, perm, b):
    if _structured_factor(lu):
        return lu.solve(b)
    return lu_solve(lu, perm, b)


def _structured_factor(lu) -> bool:
    return hasattr(lu, "solve")


def _dense(jac):
    """``[R_z, p_ref R_p]`` as a matrix."""
    if isinstance(jac, tuple):
        return jnp.concatenate([jac[0].dense(), jac[1][:, None]], axis=1)
    return jac


def _zeros_like_tree(shapes):
    return jax.tree_util.tree_map(lambda s: jax.device_put(np.zeros(s.shape, s.dtype)), shapes)


def _jacobian_is_structured(residual_and_jacobians, size, args) -> bool:
    """Whether ``R_z`` of these functions and `args` is structured: the functions' own
    ``jacobian_is_structured(*args)`` when they have one (no trace), else an abstract evaluation."""
    said = getattr(residual_and_jacobians, "jacobian_is_structured", None)
    if said is not None:
        return bool(said(*args))
    return _structured(jax.eval_shape(lambda a: residual_and_jacobians(jnp.zeros(size), 1.0, *a)[1], tuple(args)))


# ------------------------------------------------------------------------------ evaluations
def _evaluate(eq: _Equations, y):
    """``(R, [R_z, p_ref R_p])`` at ``y = (z, p / p_ref)`` (a structured ``R_z``: the pair
    ``(R_z, p_ref R_p)``).

    The callables are traced in ``(z, p, *args)``: `args` are arguments of the compiled program
    (the gear pair and its quadrature for :func:`hbgear.engine.hb.residual_functions`),
    whatever they close over is a constant in it."""
    size = eq.size
    r, jz, jp = eq.residual_and_jacobians(y[:-1], y[-1] * eq.scale, *eq.args)
    column = eq.scale * jnp.asarray(jp, dtype=float).reshape(size)
    if _structured(jz):
        return jnp.asarray(r, dtype=float).reshape(size), (jz, column)
    jac = jnp.concatenate([jnp.asarray(jz, dtype=float).reshape(size, size), column[:, None]], axis=1)
    return jnp.asarray(r, dtype=float).reshape(size), jac


def _residual_of(eq: _Equations, y):
    """``R`` at ``y`` (residual only)."""
    return jnp.asarray(eq.residual(y[:-1], y[-1] * eq.scale, *eq.args), dtype=float).reshape(eq.size)


def _constraint_ok(eq: _Equations, y):
    """``|row . y - target| <= 1e-12 (1 + |target|)``, as in the Python corrector."""
    return jnp.abs(eq.row @ y - eq.target) <= 1e-12 * (1 + jnp.abs(eq.target))


def _tangent_and_factor(jac, previous):
    """Unit tangent from ``[J; previous] t = e`` (SVD null vector if that LU is unusable),
    oriented along `previous`, and that LU as the next chord :class:`_Factor`."""
    unit_last = np.zeros(previous.shape[0])
    unit_last[-1] = 1.0
    lu, perm = _factor_bordered(jac, previous)
    raw = _solve_bordered(lu, perm, unit_last)
    ok = jnp.all(jnp.isfinite(raw))
    t = jax.lax.cond(ok, lambda: raw, lambda: jnp.linalg.svd(_dense(jac))[2][-1])
    t = t / jnp.linalg.norm(t)
    return jnp.where(t @ previous >= 0, t, -t), _Factor(lu, perm, raw, previous, ok)


# ------------------------------------------------------------------------------ chord turn
def _chord_step(eq: _Equations, chord: _Chord, y, r):
    """Modified Newton step with ``B = [J_f; row]`` from the LU of ``A = [J_f; previous_f]``:
    ``B^-1 b = u - v (d . u) / (1 + d . v)``, ``u = A^-1 b``, ``b = -(R, row . y - target)``."""
    u = _solve_bordered(chord.lu, chord.perm, -jnp.append(r, eq.row @ y - eq.target))
    return y + u - chord.v * (chord.d @ u) / chord.denominator


def _chord_turn(eq: _Equations, chord: _Chord, s: _Iterate) -> _Iterate:
    """A chord step from ``s.y``; it must halve ``max |R|``. Converged: a :data:`PREDICTOR` turn
    evaluates the Jacobian there (for the tangent); no contraction: Newton from the predictor.
    The first turn (:data:`CHORD_START`) only evaluates ``R`` at the predictor."""
    start = s.mode == CHORD_START
    cand = jax.lax.cond(start, lambda: s.y, lambda: _chord_step(eq, chord, s.y, s.r))
    r = _residual_of(eq, cand)
    norm = jnp.max(jnp.abs(r))
    it = s.it + 1
    contracted = jnp.isfinite(norm) & (norm <= 0.5 * s.norm)
    done = contracted & (norm <= eq.tolerance) & _constraint_ok(eq, cand)
    # linear convergence at the observed rate: the next step will be converged, so take it
    # and evaluate (R, R_z, R_p) there at once (the Jacobian is needed for the tangent)
    last = ~start & contracted & ~done & (norm * (norm / s.norm) <= 0.5 * eq.tolerance) & (it < eq.max_iter)
    go_on = contracted & ~done & ~last & (it < eq.max_iter)
    restart = ~done & ~go_on & ~last  # back to the predictor, Newton
    # a conditional, not a select: the speculative step is a bordered solve (at 8 DOF, H = 32, as
    # long as the residual) that a select would make at every chord turn
    cand = jax.lax.cond(last, lambda: _chord_step(eq, chord, cand, r), lambda: cand)
    it = jnp.where(last, it + 1, it)
    # leaving the chord mode: its steps are counted in chord_it, the Newton turns in it
    stepped = s._replace(it=jnp.where(go_on, it, 0).astype(jnp.int32), y=jnp.where(restart, s.y, cand),
                         r=r, norm=jnp.where(restart | last, jnp.inf, norm), cand=jnp.where(restart, eq.y_pred, cand),
                         mode=jnp.where(go_on, CHORD, PREDICTOR).astype(jnp.int32),
                         chord_it=jnp.where(go_on, 0, it).astype(jnp.int32))
    started = s._replace(r=r, norm=norm, mode=jnp.full_like(s.mode, CHORD))
    return jax.tree_util.tree_map(lambda a, b: jnp.where(start, a, b), started, stepped)


# ------------------------------------------------------------------------------ Newton turn
def _take(eq: _Equations, s: _Iterate, r_c, jac_c, norm_c) -> _Iterate:
    """The candidate becomes the iterate: test it (the Python Newton's order: non-finite,
    converged, out of iterations), else solve the bordered Newton step from it."""
    it = s.it + jnp.where(s.mode == PREDICTOR, 0, 1)
    y, residual_y = s.cand, eq.row @ s.cand - eq.target
    converged = (norm_c <= eq.tolerance) & _constraint_ok(eq, y)
    status = jnp.where(~jnp.isfinite(norm_c), _NONFINITE,
                       jnp.where(converged, _CONVERGED,
                                 jnp.where(it >= eq.max_iter, _MAX_ITERATIONS, RUNNING))).astype(jnp.int32)

    def newton_step(_):
        if isinstance(jac_c, tuple):  # a structured R_z: its bordered factorisation
            step = _solve_bordered(*_factor_bordered(jac_c, eq.row), -jnp.append(r_c, residual_y))
        else:
            a = jnp.concatenate([jac_c, eq.row[None]], axis=0)
            step = jnp.linalg.solve(a, -jnp.append(r_c, residual_y))
        ok = jnp.all(jnp.isfinite(step))
        return jnp.where(ok, y + step, y), step, jnp.where(ok, RUNNING, _SINGULAR).astype(jnp.int32)

    cand, step, status = jax.lax.cond(status < 0, newton_step, lambda _: (y, s.step, status), None)
    return s._replace(it=it.astype(jnp.int32), y=y, norm=norm_c, cand=cand, step=step,
                      mode=jnp.ones_like(s.mode), status=status)  # ones: NEWTON


def _backtrack(eq: _Equations, s: _Iterate) -> _Iterate:
    """The full step did not decrease ``max |R|``: halve it (residual only) until it does, down
    to :data:`~.corrector.LINE_SEARCH_MIN_STEP`; the result is the next candidate, taken as it is."""
    y, step, norm = s.y, s.step, s.norm

    def ls_cond(c):
        alpha, ok = c
        return (alpha > LINE_SEARCH_MIN_STEP) & ~ok

    def ls_body(c):
        alpha = 0.5 * c[0]
        n = jnp.max(jnp.abs(_residual_of(eq, y + alpha * step)))
        return alpha, jnp.isfinite(n) & (n < (1 - SUFFICIENT_DECREASE * alpha) * norm)

    alpha, _ = jax.lax.while_loop(ls_cond, ls_body, (jnp.asarray(1.0, float), jnp.asarray(False)))
    return s._replace(cand=y + alpha * step, mode=jnp.full_like(s.mode, BACKTRACKED))


def _newton_turn(eq: _Equations, s: _Iterate) -> _Iterate:
    """Evaluate ``(R, J)`` at the candidate; take it unless it is a full Newton step that does not
    decrease ``max |R|`` (then backtrack). ``s.jac`` becomes this ``J`` either way (only a taken
    candidate's is read, for the tangent at a converged one): the branches do not return it, so
    the loop writes a fresh ``J`` each turn instead of copying one through the branches."""
    r_c, jac_c = _evaluate(eq, s.cand)
    norm_c = jnp.max(jnp.abs(r_c))
    decreased = jnp.isfinite(norm_c) & (norm_c < (1 - SUFFICIENT_DECREASE) * s.norm)
    small = s._replace(jac=None)
    s = jax.lax.cond((s.mode != NEWTON) | decreased, lambda _: _take(eq, small, r_c, jac_c, norm_c),
                     lambda _: _backtrack(eq, small), None)
    return s._replace(jac=jac_c)


# ------------------------------------------------------------------------------ one corrector run
def _correct(eq: _Equations, previous, factor: _Factor, keep: _Factor):
    """One corrector run from ``eq.y_pred``; chord steps first when `factor` is usable, then
    Newton turns (the chord mode never resumes after them), in two loops: the chord loop does not
    carry a Jacobian.

    **Returns:** ``(y, max|R|, Newton iterations, chord iterations, status, tangent, factor)``,
    the tangent oriented along `previous` and `factor` the LU at ``y`` when converged, else `keep`
    (one conditional makes the new LU or passes `keep` through: no copy of either).
    """
    size, i32 = eq.size, jnp.int32
    d = eq.row - factor.previous
    chord = _Chord(factor.lu, factor.perm, factor.v, d, 1.0 + d @ factor.v)
    start_chord = factor.usable & (eq.max_iter > 0)
    if _jacobian_is_structured(eq.residual_and_jacobians, size, eq.args):
        jac0 = _zeros_like_tree(jax.eval_shape(lambda y: _evaluate(eq, y)[1], eq.y_pred))
    else:
        jac0 = jnp.zeros((size, size + 1))
    init = _Iterate(it=jnp.asarray(0, i32), y=eq.y_pred, r=jnp.zeros(size), jac=None, norm=jnp.asarray(jnp.inf),
                    cand=eq.y_pred, step=jnp.zeros(size + 1),
                    mode=jnp.where(start_chord, CHORD_START, PREDICTOR).astype(i32),
                    status=jnp.asarray(RUNNING, i32), chord_it=jnp.asarray(0, i32))
    # (`it >= 0` always holds: see _running); a chord turn leaves `status` RUNNING
    s = jax.lax.while_loop(lambda s: _running(s.mode >= CHORD, s.it), lambda s: _chord_turn(eq, chord, s), init)
    s = jax.lax.while_loop(lambda s: _running(s.status < 0, s.it), lambda s: _newton_turn(eq, s),
                           s._replace(jac=jac0))

    def failed():
        return jnp.full(size + 1, jnp.nan), keep

    t, new_factor = jax.lax.cond(s.status == _CONVERGED, lambda: _tangent_and_factor(s.jac, previous), failed)
    return s.y, s.norm, s.it, s.chord_it, s.status, t, new_factor


# ------------------------------------------------------------------------------ segment loop
def _is_regular(s: _Segment, y, t, converged, controls: SegmentControls, budget):
    """The acceptance tests of :mod:`.driver` for a regular step: converged, within ``ds`` of the
    predictor, turned by at most ``max_angle_deg`` (both waived at ``ds_min``), no fold, not at or
    past ``p_end``, not back past ``p_start``, and within the `budget`. Also the angle [deg]."""
    c = controls
    angle = jnp.degrees(jnp.arccos(jnp.clip(t @ s.t, -1.0, 1.0)))
    offset = jnp.linalg.norm(y - s.y_pred)
    ds = s.ds
    regular = (converged & ~((offset > ds) & (ds > c.ds_min)) & ~((angle > c.max_angle_deg) & (ds > c.ds_min))
               & (t[-1] * s.t[-1] >= 0) & ((y[-1] - c.p_end) * c.direction < 0)
               & ~(((y[-1] - c.p_start) * c.direction < 0) & ((s.y[-1] - c.p_start) * c.direction >= 0))
               & (s.k < budget))
    return regular, angle


def _segment_turn(problem, max_iter, tolerance, scale, use_chord, budget, controls: SegmentControls, args,
                  s: _Segment) -> _Segment:
    """One corrector run from ``s.y_pred``; a regular step is stored and the next predictor made
    (step-size control and parameter-step limit of :mod:`.driver`), else the run is kept as
    `pending` and the segment ends."""
    c = controls
    eq = _Equations(*problem, scale, args, s.y_pred, s.row, s.target, max_iter, tolerance)
    y, norm, newton_it, chord_it, status, t, factor = _correct(
        eq, s.previous, s.factor._replace(usable=s.factor.usable & use_chord), s.factor)
    converged = status == _CONVERGED
    regular, angle = _is_regular(s, y, t, converged, c, budget)
    ds = s.ds
    work = newton_it + CHORD_ITERATION_WORK * chord_it
    ds_next = _grown_step(ds, work, angle, c.ds_min, c.ds_max, c.max_angle_deg, c.growth, c.target_iterations, jnp)
    ds_next = _limited_step(ds_next, t[-1], c.ds_min, c.max_parameter_step, jnp)
    y_next = y + ds_next * t
    k = s.k
    info = jnp.stack([norm, (newton_it + chord_it).astype(float), ds])
    pending = jnp.concatenate([y, t, jnp.stack([norm, newton_it.astype(float), chord_it.astype(float),
                                                status.astype(float), 1.0])])
    taken = _Segment(k=k + 1, y=y, t=t, ds=ds_next, factor=factor, y_pred=y_next, row=t, target=t @ y_next,
                     previous=t, done=k + 1 >= budget, pending=s.pending,
                     y_out=s.y_out.at[k].set(y), t_out=s.t_out.at[k].set(t), info=s.info.at[k].set(info))
    refused = s._replace(done=jnp.asarray(True), pending=pending, factor=factor)
    return jax.lax.cond(regular, lambda: taken, lambda: refused)


def _dtype(leaf) -> np.dtype:
    return np.dtype(leaf.dtype) if hasattr(leaf, "dtype") else np.result_type(leaf)


def _signature(args):
    """What a trace of `args` depends on: their tree structure with its classes (the structure
    alone does not tell all classes apart: :mod:`~hbgear.engine.typed_jit`) and each leaf's shape
    and dtype (``None`` if that is not hashable)."""
    leaves, tree = jax.tree_util.tree_flatten(tuple(args))
    try:
        key = (tree, node_types(tuple(args)), tuple((np.shape(leaf), _dtype(leaf).str) for leaf in leaves))
        hash(key)
    except TypeError:
        return None
    return key


def _jit_corrector(residual_and_jacobians, residual, size):
    """The corrector of :func:`~.corrector._python_corrector`, and the regular continuation steps
    around it, as one compiled JAX function (``advance``), and ``no_factor`` (an unusable chord LU).
    """
    problem = (residual_and_jacobians, residual, size)
    structured_lu = BoundedCache(8)  # abstract signature of `args` -> zeros of the structured LU, or None (dense)

    def no_factor(previous, args=()):
        """An unusable factorisation: zeros of the dense LU's shape or, when the Jacobian of these
        `args` is structured, of its factorisation's (found by an abstract evaluation, once per
        signature of `args`: a trace of the residual functions costs milliseconds of Python,
        a fifth of a Duffing curve of 167 points)."""

        def zeros():
            if not _jacobian_is_structured(residual_and_jacobians, size, args):
                return None

            def factor(a, prev):
                eq = _Equations(*problem, 1.0, a, prev, prev, 0.0, 0, 0.0)
                lu, _ = _factor_bordered(_evaluate(eq, prev)[1], prev)
                return lu

            previous_shape = jax.ShapeDtypeStruct(np.shape(previous), np.float64)
            return _zeros_like_tree(jax.eval_shape(factor, tuple(args), previous_shape))

        key = _signature(args)
        lu = zeros() if key is None else structured_lu.get_or_make(key, zeros)
        return _no_factor(size, previous, lu)

    @typed_jit
    def advance(y_pred, row, target, previous, max_iter, tolerance, factor, scale, use_chord, y0, t0, ds0, budget,
                controls, args=()):
        """Corrector runs from ``y_pred`` and then, while each is a regular continuation step from
        ``(y0, t0, ds0)`` and fewer than `budget` were taken, the next predictor-corrector steps
        with the step-size control of :func:`continuation` (`controls` a :class:`SegmentControls`).
        Regular: see :func:`_is_regular`.

        **Returns:** ``(taken, points, (y, t, ds), factor, pending)``: `taken` regular steps,
        `points` their ``(y, t, max|R|, iterations, ds)`` stacked (``SEGMENT_POINTS`` rows,
        the first `taken` valid), the state after them, the chord LU, and ``pending`` = ``[y,
        tangent, max|R|, Newton iterations, chord iterations, status, valid]`` of the last
        corrector run when it was not a regular step (for the caller to decide on; one array:
        one transfer). With ``budget = 0`` it is one plain corrector run.
        """
        controls = SegmentControls(*controls)
        m = size + 1
        rows = SEGMENT_POINTS
        state = _Segment(k=jnp.asarray(0, jnp.int32), y=y0, t=t0, ds=ds0, factor=factor, y_pred=y_pred, row=row,
                         target=target, previous=previous, done=jnp.asarray(False), pending=jnp.zeros(2 * m + 5),
                         y_out=jnp.zeros((rows, m)), t_out=jnp.zeros((rows, m)), info=jnp.zeros((rows, 3)))

        def turn(s):
            return _segment_turn(problem, max_iter, tolerance, scale, use_chord, budget, controls, args, s)

        s = jax.lax.while_loop(lambda s: _running(~s.done, s.k), turn, state)
        return s.k, (s.y_out, s.t_out, s.info), (s.y, s.t, s.ds), s.factor, s.pending

    # residual functions that say what they close over (``program_key``, e.g. the harmonic
    # balance settings) let the traced corrector be kept on disk (hbgear.engine.persistent)
    key = getattr(residual_and_jacobians, "program_key", None)
    advance.program_key = None if key is None or getattr(residual, "program_key", None) != key else (key, size)
    return advance, no_factor


class _Compiled:
    """One run's use of the compiled corrector: a plain corrector call (``self(...)``, the
    interface of :func:`~.corrector._python_corrector`) or a :meth:`segment` of regular steps;
    with `chord` it keeps the LU of the last converged point for the next call."""

    def __init__(self, compiled, chord: bool, scale: float, controls=None, args=()):
        advance, no_factor = compiled
        self.args = tuple(args)
        self.advance = advance.typed_for(args=self.args)  # the classes of the system walked once, not per call
        if advance.program_key is not None:
            self.advance = persistent(self.advance, "advance", advance.program_key)
        self.chord, self.scale = bool(chord), float(scale)
        self.controls = SegmentControls(*(np.float64(c) for c in (np.zeros(9) if controls is None else controls)))
        self.last = None
        self.empty = None
        self.no_factor = no_factor

    def _factor(self, previous):
        if self.chord and self.last is not None:
            return self.last
        # "no factorisation": device-resident zeros made once, only `previous` changes
        if self.empty is None:
            self.empty = self.no_factor(jax.device_put(np.asarray(previous, dtype=float)), args=self.args)
        return self.empty._replace(previous=np.asarray(previous, dtype=float))

    def _run(self, y_pred, row, target, previous, max_iter, tolerance, y0, t0, ds0, budget):
        return self.advance(y_pred, row, float(target), previous, int(max_iter), float(tolerance),
                            self._factor(previous), self.scale, self.chord, y0, t0, float(ds0), int(budget),
                            self.controls, args=self.args)

    def _result(self, pending, factor, max_iter):
        """A corrector run's packed outcome -> _Point | _Failure (keeps the LU if converged)."""
        m = (pending.size - 5) // 2
        y, t = pending[:m], pending[m : 2 * m]
        norm, newton_it, chord_it, status = float(pending[-5]), int(pending[-4]), int(pending[-3]), int(pending[-2])
        if status == _CONVERGED:
            self.last = factor
            return _Point(y, norm, t, newton_it + chord_it, newton_it + CHORD_ITERATION_WORK * chord_it)
        return _failure(status, norm, newton_it + chord_it, max_iter)

    def __call__(self, y_pred, row, target, previous, max_iter, tolerance):
        y_pred = np.asarray(y_pred, dtype=float)
        _, _, _, factor, pending = self._run(y_pred, row, target, previous, max_iter, tolerance, y_pred,
                                             np.asarray(row, dtype=float), 0.0, 0)
        return self._result(np.asarray(jax.device_get(pending)), factor, max_iter)

    def segment(self, y, t, ds, max_iter, tolerance, budget):
        """Up to `budget` regular steps from ``(y, t, ds)`` in one call.

        **Returns:** ``(points, pending, (y, t, ds))``: the regular points as ``(y, t, max|R|,
        iterations, ds)``, then the outcome of the corrector run that was not a regular step
        (``None`` if the budget ran out first) and the state it started from.
        """
        y_pred = y + ds * t
        taken, (y_out, t_out, info), state, factor, pending = self._run(
            y_pred, t, t @ y_pred, t, max_iter, tolerance, y, t, ds, min(budget, SEGMENT_POINTS))
        taken, y_out, t_out, info, state, pending = jax.device_get((taken, y_out, t_out, info, state, pending))
        points = [(y_out[i], t_out[i], float(info[i, 0]), int(info[i, 1]), float(info[i, 2]))
                  for i in range(int(taken))]
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
