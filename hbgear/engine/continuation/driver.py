"""The driver, :func:`continuation`: the start, the loop of predictor-corrector steps with their
acceptance, the fold insertion, the landing on ``p_end`` and the stops (the algorithm is
described in :mod:`hbgear.engine.continuation`)."""

from __future__ import annotations

import math
import sys
import time
import warnings
from pathlib import Path
from typing import Callable, NamedTuple

import numpy as np

from ..condensed import as_matrix
from ..newton import NewtonResult, NewtonStatus, newton
from .branch import MESSAGES, Branch, PointKind, Status
from .compiled import _JIT_CACHE, SegmentControls, _cached_jit_corrector, _Compiled
from .corrector import _Failure, _Point, _python_corrector
from .folds import _locate_fold
from .options import PseudoArclength
from .progress import _advance_bar, _progress_bar
from .steps import _angle_deg, _grown_step, _limited_step

__all__ = ["continuation", "solve_at_parameter"]

_PACKAGE = str(Path(__file__).resolve().parent)


def _caller_stacklevel() -> int:
    """``stacklevel`` of the first frame outside this package (a warning points at the user's call)."""
    frame, level = sys._getframe(1), 1
    while frame is not None and frame.f_code.co_filename.startswith(_PACKAGE):
        frame, level = frame.f_back, level + 1
    return level


def _dense_pair(evaluation):
    """``(R, R_z)`` of an evaluation ``(R, R_z, R_p)``, a structured ``R_z`` as a matrix."""
    return evaluation[0], as_matrix(evaluation[1])


class _Correctors:
    """The run's corrector ``(y_pred, row, target, max_iter, previous[, tol]) -> _Point |
    _Failure``: the compiled one (with `jit_step`) until the residual functions turn out not to
    be traceable by JAX, then, with a warning, the Python one (the same algorithm)."""

    def __init__(self, functions, bound, scale, size, method, controls, args, tolerance):
        self.python = _python_corrector(*bound, scale, size)
        self.tolerance = tolerance
        self._key = (*functions, size)
        self.compiled = None
        if method.jit_step:  # the same callables again (e.g. repeated runs): no new trace
            self.compiled = _Compiled(_cached_jit_corrector(*functions, size), method.chord, scale, controls, args)

    def __call__(self, y_pred, row, target, max_iter, previous, tol=None):
        """Newton on ``R(y) = 0``, ``row . y = target``; a _Point (with the tangent oriented
        along `previous`) or a _Failure."""
        tol = self.tolerance if tol is None else tol
        if self.compiled is None:
            return self.python(y_pred, row, target, previous, max_iter, tol)
        try:
            return self.compiled(y_pred, row, target, previous, max_iter, tol)
        except Exception as error:  # not traceable by JAX: the Python corrector, same algorithm
            self.fall_back(error)
            return self.python(y_pred, row, target, previous, max_iter, tol)

    def fall_back(self, error):
        """Use the Python corrector from now on (and forget the compiled one of these functions)."""
        warnings.warn(f"jit_step: the residual functions could not be compiled ({type(error).__name__}: "
                      f"{str(error).splitlines()[0] if str(error) else ''}); using the Python corrector",
                      RuntimeWarning, stacklevel=_caller_stacklevel())
        self.compiled = None
        _JIT_CACHE.pop(self._key, None)


def _compiled_fixed_point(correct: _Correctors, z0, p, scale, seed, max_iterations, tolerance, residual):
    """One compiled corrector run at fixed ``p`` (the bordered row ``e_p``) from ``(z0, p)``, its
    tangent oriented along `seed`: a :class:`_Point`, or ``None`` when there is no compiled
    corrector or it did not converge."""
    if correct.compiled is None:
        return None
    y_guess, fixed_p = np.append(z0, p / scale), np.abs(seed)
    try:
        point = correct.compiled(y_guess, fixed_p, p / scale, seed, max_iterations, tolerance)
    except Exception:  # noqa: BLE001 -- e.g. a closure that fills a cache on its first call,
        residual(z0, float(p))  # which must be eager: call it once, then trace again
        point = correct(y_guess, fixed_p, p / scale, max_iterations, seed)  # or fall back
    return point if isinstance(point, _Point) else None


def solve_at_parameter(residual_and_jacobians, residual, z0, p: float, *, args=(), tolerance: float = 1e-9,
                       max_iterations: int = 50) -> NewtonResult:
    """``R(z; p) = 0`` at fixed `p` by the corrector a :func:`continuation` of the same functions
    runs (``jit_step``): the same compiled program (no compilation of its own once a continuation
    of these functions and argument shapes has run), the bordered row fixing ``p``; if that
    corrector does not converge or cannot be compiled, the engine's Newton
    (:func:`~hbgear.engine.newton.newton`), which compiles the residual functions on their own.

    **Returns:** a :class:`~hbgear.engine.newton.NewtonResult` (no Jacobian).
    """
    z0, args = np.asarray(z0, dtype=float), tuple(args)
    scale = abs(float(p)) or 1.0
    functions = (residual_and_jacobians, residual)
    bound = _bound(functions, args)
    correct = _Correctors(functions, bound, scale, z0.size, PseudoArclength(jit_step=True), None, args, tolerance)
    seed = np.zeros(z0.size + 1)
    seed[-1] = 1.0
    point = _compiled_fixed_point(correct, z0, p, scale, seed, max_iterations, tolerance, bound[1])
    if point is not None:
        return NewtonResult(point.y[:-1], NewtonStatus.CONVERGED, point.iterations, point.r_norm)
    return _engine_newton(*bound, z0, p, tolerance, max_iterations)


def _bound(functions, args):
    """``(residual_and_jacobians, residual)`` of ``(z, p)`` with the extra `args` bound."""
    if not args:
        return functions
    residual_and_jacobians, residual = functions
    return (lambda z, p: residual_and_jacobians(z, p, *args)), (lambda z, p: residual(z, p, *args))


def _engine_newton(residual_and_jacobians, residual, z0, p, tolerance, max_iterations):
    """The engine's Newton (:func:`~hbgear.engine.newton.newton`) at fixed `p` on the bound functions."""
    return newton(lambda z: _dense_pair(residual_and_jacobians(z, float(p))), lambda z: residual(z, float(p)), z0,
                  tolerance=tolerance, max_iterations=max_iterations)


class _Record:
    """The stored points, all converged, in path order; a `callback` returning ``True`` sets
    `stopped`."""

    FIELDS = ("p", "z", "kind", "iterations", "residual", "tangent_p", "ds")

    def __init__(self, size, scale, callback):
        self.rows = {k: [] for k in self.FIELDS}
        self.size, self.scale, self.callback = size, scale, callback
        self.stopped = False

    def __len__(self) -> int:
        return len(self.rows["p"])

    def store(self, y, kind, iterations, r_norm, t, ds, p=None):
        """Store the point ``y = (z, p / p_ref)`` (`p`: its exact parameter, if given)."""
        rows = self.rows
        rows["p"].append(y[-1] * self.scale if p is None else p)
        rows["z"].append(y[:-1].copy())
        rows["kind"].append(int(kind))
        rows["iterations"].append(iterations)
        rows["residual"].append(r_norm)
        rows["tangent_p"].append(float(t[-1]))
        rows["ds"].append(ds)
        if self.callback is not None and self.callback(float(rows["p"][-1]), y[:-1].copy()):
            self.stopped = True

    def branch(self, status, detail, rejected, start_seconds) -> Branch:
        """The :class:`Branch` of the stored points, `detail` put before the status's message."""
        rows = self.rows
        message = MESSAGES[status] if not detail else f"{detail}. {MESSAGES[status]}"
        return Branch(
            p=np.asarray(rows["p"], dtype=float),
            z=np.asarray(rows["z"], dtype=float) if rows["z"] else np.zeros((0, self.size)),
            kind=np.asarray(rows["kind"], dtype=np.int8),
            iterations=np.asarray(rows["iterations"], dtype=int),
            residual=np.asarray(rows["residual"], dtype=float),
            tangent_p=np.asarray(rows["tangent_p"], dtype=float),
            ds=np.asarray(rows["ds"], dtype=float),
            status=status,
            message=message,
            parameter_scale=self.scale,
            rejected=rejected,
            start_seconds=start_seconds,
        )


class _Stop(NamedTuple):
    status: Status
    detail: str = ""


class _Run:
    """One continuation run: the current point ``(y, t)`` and step ``ds``, the corrector, the
    record and the progress bar. Each method is one part of :func:`continuation`'s loop."""

    def __init__(self, functions, bound, args, record, method, p0, p_end, scale, tolerance, max_points):
        self.record, self.m = record, method
        self.p0, self.p_end, self.scale = p0, p_end, scale
        self.tolerance, self.max_points = tolerance, max_points
        self.direction = 1.0 if p_end > p0 else -1.0
        self.end_scaled = p_end / scale
        self.max_parameter_step = math.inf if method.max_parameter_step is None else method.max_parameter_step
        m = method
        controls = SegmentControls(m.ds_min, m.ds_max, m.max_angle_deg, m.growth, m.target_iterations,
                                   self.max_parameter_step, p_end / scale, self.direction, p0 / scale)
        self.correct = _Correctors(functions, bound, scale, record.size, m, controls, args, tolerance)
        self.rejected = 0
        self.bar = None
        self.y = self.t = None
        self.ds = method.ds

    # -- start ---------------------------------------------------------------------------
    def start(self, z0, start_iterations, residual_and_jacobians, residual) -> _Stop | None:
        """Newton at fixed ``p0`` and the tangent there, oriented towards ``p_end``; stores the
        start point. Compiled: one call of the compiled corrector (no separately compiled
        residual functions needed); otherwise, or if it fails, the engine's Newton.

        **Returns:** ``None``, or the :attr:`Status.START_FAILED` stop.
        """
        p0, scale = self.p0, self.scale
        seed = np.zeros(z0.size + 1)
        seed[-1] = self.direction
        fixed_p = np.abs(seed)
        first = _compiled_fixed_point(self.correct, z0, p0, scale, seed, start_iterations, self.tolerance, residual)
        if first is None:
            start = _engine_newton(residual_and_jacobians, residual, z0, p0, self.tolerance, start_iterations)
            if not start.converged:
                return _Stop(Status.START_FAILED,
                             f"Newton at p = {p0:.9g} reached max|R| = {start.residual_norm:.3e} > tolerance "
                             f"{self.tolerance:.1e} after {start.iterations} iterations")
            y = np.append(np.asarray(start.z, dtype=float), p0 / scale)
            first = self.correct(y, fixed_p, y[-1], 0, seed, tol=math.inf)  # R, J at the start: the tangent
            if not isinstance(first, _Point):
                return _Stop(Status.START_FAILED,
                             f"the Jacobian at p = {p0:.9g} could not be evaluated: {first.reason}")
            first = first._replace(iterations=start.iterations)
        self.y, t = first.y, first.tangent
        if t[-1] * self.direction <= 0:  # started on a fold or against the range: push towards p_end
            t = -t if t[-1] * self.direction < 0 else t
        self.t = t
        self.record.store(self.y, PointKind.START, first.iterations, first.r_norm, t, 0.0, p=float(p0))
        return None

    # -- the loop ------------------------------------------------------------------------
    def follow(self) -> _Stop:
        """Steps until a stop: the callback, ``max_points``, no acceptable step, ``p_end``
        reached, or the branch turned back past ``p0``."""
        record, m = self.record, self.m
        while True:
            if record.stopped:
                return _Stop(Status.STOPPED)
            if len(record) >= self.max_points:
                return _Stop(Status.MAX_POINTS,
                             f"{self.max_points} points stored, last at p = {self.y[-1] * self.scale:.9g}")
            self.ds = float(_limited_step(self.ds, self.t[-1], m.ds_min, self.max_parameter_step))
            pending = None
            if self.correct.compiled is not None:  # regular steps in one compiled call
                again, pending = self._segment()
                if again:
                    continue  # stopped, at max_points, or the next segment
            step = self._step(pending)
            if isinstance(step, _Stop):
                return step
            stop = self._after_step(*step)
            if stop is not None:
                return stop

    def _segment(self):
        """Regular steps by one call of the compiled corrector, stored.

        **Returns:** ``(again, pending)``: `again` to go back to the top of the loop (stopped, at
        ``max_points``, the budget used up, or the compiled corrector given up), else
        `pending` is the corrector outcome of the step that was not regular.
        """
        record = self.record
        pending = None
        try:
            points, pending, (self.y, self.t, self.ds) = self.correct.compiled.segment(
                self.y, self.t, self.ds, self.m.max_corrector_iterations, self.tolerance, self.max_points - len(record))
        except Exception as error:  # not traceable by JAX: the Python corrector from here
            self.correct.fall_back(error)
            points = []
        for y_new, t_new, r_norm, iterations, ds_used in points:
            record.store(y_new, PointKind.REGULAR, iterations, r_norm, t_new, ds_used)
            if record.stopped:
                break
        if points:
            self._show()
        return record.stopped or pending is None, pending

    def _step(self, pending):
        """One accepted step from ``(y, t)``: the predictor ``y + ds t`` corrected (or
        `pending`, the compiled segment's run from it), ``ds`` halved after each refusal.

        **Returns:** ``(point, angle)``: the accepted :class:`_Point` and the tangents' angle
        [deg]; or the :attr:`Status.STEP_TOO_SMALL` stop, saying what was tried.
        """
        m, y, t = self.m, self.y, self.t
        tried = []
        while True:
            y_pred = y + self.ds * t
            if pending is not None:  # the segment's last corrector run, from this predictor
                result, pending = pending, None
            else:
                result = self.correct(y_pred, t, t @ y_pred, m.max_corrector_iterations, t)
            result, angle = self._accepted(result, y_pred)
            if isinstance(result, _Point):
                return result, angle
            tried.append((self.ds, f"ds={self.ds:.3g}: {result.reason} (max|R|={result.r_norm:.2e})"))
            self.rejected += 1
            if self.ds <= m.ds_min:
                return _Stop(Status.STEP_TOO_SMALL, (
                    f"stuck at p = {y[-1] * self.scale:.9g} (tangent p-component {t[-1]:+.3g}, "
                    f"max|R| = {float(self.record.rows['residual'][-1]):.2e} there): {len(tried)} step sizes tried "
                    f"from ds = {float(tried[0][0]):.3g} down to ds_min = {m.ds_min:.3g}, the last: "
                    + "; ".join(text for _, text in tried[-3:])))
            self.ds = max(m.ds_min, 0.5 * self.ds)

    def _accepted(self, result, y_pred):
        """The acceptance test of a converged corrector run (module doc, item 4): it moved at
        most ``ds`` off the predictor and the tangent turned by at most ``max_angle_deg``, both
        waived at ``ds_min``. **Returns:** ``(result or a _Failure, angle [deg] or None)``."""
        if not isinstance(result, _Point):
            return result, None
        m, ds = self.m, self.ds
        angle = _angle_deg(result.tangent, self.t)
        offset = float(np.linalg.norm(result.y - y_pred))
        if offset > ds and ds > m.ds_min:
            reason = f"corrector moved {offset:.2e} > ds off the predictor"
        elif angle > m.max_angle_deg and ds > m.ds_min:
            reason = f"tangent turned {angle:.1f} deg > {m.max_angle_deg:g}"
        else:
            return result, angle
        return _Failure(reason, result.r_norm, result.iterations), angle

    def _after_step(self, point, angle) -> _Stop | None:
        """After an accepted step to `point`: a fold on the way is inserted, the end of the range
        or a turn back past ``p0`` stops the run; else the point is stored and ``ds`` adapted.

        **Returns:** a stop, or ``None`` to go on.
        """
        y_new, t_new = point.y, point.tangent
        if t_new[-1] * self.t[-1] < 0 and self._insert_fold(y_new, float(t_new[-1])):
            return None  # at max_points: the loop stops at the fold
        if (y_new[-1] - self.end_scaled) * self.direction >= 0:
            return self._land_on_end(y_new)
        if self._turned_back(y_new):
            self.record.store(y_new, PointKind.REGULAR, point.iterations, point.r_norm, t_new, self.ds)
            return _Stop(Status.TURNED_BACK, f"at p = {y_new[-1] * self.scale:.9g}")
        self.record.store(y_new, PointKind.REGULAR, point.iterations, point.r_norm, t_new, self.ds)
        m = self.m
        self.ds = float(_grown_step(self.ds, point.work, angle, m.ds_min, m.ds_max, m.max_angle_deg, m.growth,
                                    m.target_iterations))
        self.y, self.t = y_new, t_new
        self._show()
        return None

    def _insert_fold(self, y_new, g_new) -> bool:
        """The p-component of the tangent changed sign between ``y`` and `y_new`: locate the fold
        and store it if it lies before ``p_end``. **Returns:** ``True`` if ``max_points`` is then
        reached (the run moves to the fold, and stops there)."""
        y, t = self.y, self.t
        fold = _locate_fold(self.correct, y, t, y_new, g_new, self.m.max_corrector_iterations)
        if fold is None or (fold.y[-1] - self.end_scaled) * self.direction >= 0:
            return False
        self.record.store(fold.y, PointKind.FOLD, fold.iterations, fold.r_norm, fold.tangent, float(t @ (fold.y - y)))
        if len(self.record) >= self.max_points:
            self.y, self.t = fold.y, fold.tangent
            return True
        return False

    def _land_on_end(self, y_new) -> _Stop | None:
        """The step crossed ``p_end``: solve at ``p = p_end`` from the interpolated guess and
        stop with :attr:`Status.SUCCESS`; if that fails, halve ``ds`` to come closer first
        (``None``: go on), down to ``ds_min`` (:attr:`Status.STEP_TOO_SMALL`)."""
        y, end, m = self.y, self.end_scaled, self.m
        frac = (end - y[-1]) / (y_new[-1] - y[-1])
        guess = y + frac * (y_new - y)
        row = np.zeros(y.size)
        row[-1] = 1.0
        last = self.correct(guess, row, end, m.max_corrector_iterations, self.t)
        if isinstance(last, _Point):
            self.record.store(last.y, PointKind.END, last.iterations, last.r_norm, last.tangent,
                              float(np.linalg.norm(last.y - y)), p=float(self.p_end))
            return _Stop(Status.SUCCESS)
        self.ds = max(m.ds_min, 0.5 * self.ds)
        if self.ds > m.ds_min:
            return None
        return _Stop(Status.STEP_TOO_SMALL,
                     f"could not solve at p_end = {self.p_end:.9g}: {last.reason} (max|R|={last.r_norm:.2e})")

    def _turned_back(self, y_new) -> bool:
        """The step went from at or past ``p0`` (in the direction of travel) to before it."""
        start = self.p0 / self.scale
        return ((y_new[-1] - start) * self.direction < 0 and (self.y[-1] - start) * self.direction >= 0
                and len(self.record) > 1)

    def _show(self):
        if self.bar is not None:
            _advance_bar(self.bar, self.y, self.scale, self.p0, self.p_end, len(self.record), self.ds)


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
    z0 = np.asarray(z0, dtype=float)
    args = tuple(args)
    functions = (residual_and_jacobians, residual)  # traced by the compiled corrector with `args`
    residual_and_jacobians, residual = _bound(functions, args)
    run = _Run(functions, (residual_and_jacobians, residual), args, _Record(z0.size, scale, callback), m, p0, p_end,
               scale, tolerance, max_points)
    clock_start = time.perf_counter()
    stop = run.start(z0, start_iterations, residual_and_jacobians, residual)
    if stop is not None:
        return run.record.branch(stop.status, stop.detail, run.rejected, 0.0)
    start_seconds = time.perf_counter() - clock_start
    run.bar = _progress_bar(progress, p0, p_end)
    try:
        stop = run.follow()
    finally:
        if run.bar is not None:
            run.bar.close()
    return run.record.branch(stop.status, stop.detail, run.rejected, start_seconds)
