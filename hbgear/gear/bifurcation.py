r"""Bifurcations of the gear pair's periodic steady states (MODEL.md sections 5, 6 and 8).

The gear-pair forms (models, speeds) of :mod:`hbgear.engine.bifurcation`, each checked against
time integration in ``tests/test_bifurcation.py`` and ``validation/``:

- **Period doubling -> the** ``nu = 2`` **branch**: :func:`locate_period_doubling` (the engine's one
  locator between two speeds) and :func:`continue_period_doubled` (its one follower, until a
  given speed); :func:`solve_period_doubled` converges one ``nu = 2`` solution from a given start
  and rejects a collapse back onto the ``nu = 1`` solution.
- **Backlash folds** (:func:`backlash_frc`): the frequency-response curve through both turning
  points of the softening contact-loss resonance, with the fold speeds.
- **Time-integration sweeps** (:func:`ti_sweep`, :func:`jump_speeds`): the speed is stepped and
  every run starts from the previous run's steady state, so the hysteresis of the jumps shows;
  the jump speeds are bracketed by bisection.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..engine import bifurcation as _engine
from ..engine.bifurcation import embed_subharmonic, half_order_indices, half_order_mode, half_order_share
from ..engine.continuation import Branch, Status
from ..engine.hb import HarmonicBalance
from ..errors import ConvergenceError
from .simulate import simulate
from .solve import PeriodicSolution, rad_s_to_rpm, rpm_to_rad_s, solve_periodic
from .system import GearSystem

__all__ = [
    "embed_subharmonic",
    "half_order_indices",
    "half_order_mode",
    "half_order_share",
    "PeriodDoublingPoint",
    "period_doubling_multiplier",
    "locate_period_doubling",
    "solve_period_doubled",
    "SubharmonicBranch",
    "continue_period_doubled",
    "FoldCurve",
    "backlash_frc",
    "SweepResult",
    "ti_sweep",
    "JumpResult",
    "jump_speeds",
]


class PeriodDoublingPoint(NamedTuple):
    """A located period doubling: speed `omega` [rad/s] (`speed_rpm`), the ``nu = 1`` solution
    there, the real multiplier nearest -1 (per mesh period) and the speed bracket it came from."""

    omega: float
    speed_rpm: float
    solution: PeriodicSolution
    multiplier: float
    bracket_rpm: tuple


def period_doubling_multiplier(model, solution: PeriodicSolution) -> float:
    """The most negative real Floquet multiplier per mesh period of a ``nu = 1`` solution (``nan``
    if none): exact monodromy where the model is linear along it, the variational equations
    otherwise (:func:`hbgear.engine.bifurcation.exact_negative_multiplier`)."""
    if solution.nu != 1:
        raise ValueError("period_doubling_multiplier needs a nu = 1 solution")
    return _engine.exact_negative_multiplier(GearSystem(model), solution.hb, solution.z, solution.omega_pinion)


def locate_period_doubling(model, omega_a: float, omega_b: float, *, harmonics: int = 16, samples: int | None = None,
                           tolerance: float = 1e-9, speed_tolerance: float = 1e-6, max_steps: int = 40
                           ) -> PeriodDoublingPoint:
    """The speed between `omega_a` and `omega_b` [rad/s] where a multiplier crosses -1
    (:func:`hbgear.engine.bifurcation.locate_period_doubling` between the two ``nu = 1`` solutions).

    **Raises:** `ValueError` if the exact multipliers there do not bracket a crossing.
    """
    solve = lambda w, z0=None: solve_periodic(model, w, harmonics=harmonics, nu=1, samples=samples,  # noqa: E731
                                              tolerance=tolerance, z0=z0)
    a, b = solve(float(omega_a)), solve(float(omega_b))
    point, why = _engine.locate_period_doubling(GearSystem(model), a.hb, lambda w, z0: solve(w, z0).z, a.omega_pinion,
                                                a.z, b.omega_pinion, b.z, tolerance=speed_tolerance,
                                                max_steps=max_steps)
    if point is None:
        raise ValueError(f"{rad_s_to_rpm(omega_a):.6g} and {rad_s_to_rpm(omega_b):.6g} rpm do not bracket a multiplier "
                         f"crossing -1: {why}")
    sol = PeriodicSolution.from_z(model, point.p, point.z, a.hb)
    return PeriodDoublingPoint(point.p, rad_s_to_rpm(point.p), sol, point.multiplier,
                               (rad_s_to_rpm(omega_a), rad_s_to_rpm(omega_b)))


def solve_period_doubled(model, omega: float, z0, *, harmonics: int, samples: int | None = None,
                         tolerance: float = 1e-9, max_iterations: int = 50, min_share: float = 1e-3) -> PeriodicSolution:
    """One ``nu = 2`` solution by :func:`~hbgear.gear.solve.solve_periodic` from `z0` (e.g. an
    embedded ``nu = 1`` solution plus a half-order perturbation, or a neighbour on the branch).

    **Raises:** :class:`~hbgear.errors.ConvergenceError` if Newton fails, or if it converged
    back onto a ``T_m``-periodic solution (half-order share of the DTE below `min_share`).
    """
    samples = samples or max(256, 8 * harmonics)
    sol = solve_periodic(model, omega, harmonics=harmonics, nu=2, samples=samples, tolerance=tolerance,
                         max_iterations=max_iterations, z0=np.asarray(z0, dtype=float))
    share = half_order_share(sol.z, model.ndof, harmonics)
    if share < min_share:
        raise ConvergenceError(
            f"nu = 2 harmonic balance at {rad_s_to_rpm(omega):.6g} rpm converged back to a period-1 solution "
            f"(half-order share {share:.2e} < {min_share:g}); start closer to the period-doubled branch "
            "(continue_period_doubled)"
        )
    return sol


@dataclass(frozen=True)
class SubharmonicBranch:
    """A continued ``nu = 2`` branch, in path order from the bifurcation.

    **Fields:** `omega` (n,) pinion speeds [rad/s]; `z` (n, size) scaled unknowns of `hb` (the
    ``nu = 2`` discretisation); `amplitude` (n,) the half-order amplitude ``phi . (z - z_*)``
    [static deflections]; `model`; `bifurcation` (:class:`PeriodDoublingPoint`); `reached`
    (the last point is solved exactly at the requested end speed); `status`, `message` (of the
    follower, :class:`hbgear.engine.bifurcation.DoubledBranch`); `mode` ``phi``.
    """

    omega: np.ndarray
    z: np.ndarray
    amplitude: np.ndarray
    hb: HarmonicBalance
    model: object
    bifurcation: PeriodDoublingPoint
    reached: bool
    status: str
    message: str
    mode: np.ndarray

    @property
    def speed_rpm(self) -> np.ndarray:
        return rad_s_to_rpm(np.asarray(self.omega))

    def solution(self, i: int = -1) -> PeriodicSolution:
        return PeriodicSolution.from_z(self.model, float(self.omega[i]), self.z[i], self.hb)

    def dte_p2p_um(self) -> np.ndarray:
        scale = float(GearSystem(self.model).displacement_scale)
        return np.array([_dense_p2p_um(z, self.hb, scale) for z in self.z])

    @property
    def fold_speeds_rpm(self) -> np.ndarray:
        """Speeds where the branch turns (local extrema of the speed along the path; coarse)."""
        w = np.asarray(self.omega)
        d = np.diff(w)
        return rad_s_to_rpm(w[np.flatnonzero(d[:-1] * d[1:] < 0) + 1])


def continue_period_doubled(model, point: PeriodDoublingPoint, omega_end: float, *, harmonics: int | None = None,
                            samples: int | None = None, amplitude: float = 0.02, max_amplitude: float = 100.0,
                            tolerance: float = 1e-9, max_points: int = 400) -> SubharmonicBranch:
    r"""Follow the period-doubled branch born at `point` until it reaches the speed `omega_end`
    (:func:`hbgear.engine.bifurcation.follow_period_doubled`: continuation in the half-order
    amplitude with the speed free, regular at the bifurcation whatever the branch does there, then
    an arclength leg in speed that stops exactly at `omega_end`).

    **Arguments:** `harmonics`: ``H2`` (default ``2 H``); `samples`: its AFT samples (default
    ``max(256, 8 H2)``); `amplitude`, `max_amplitude`: of the half orders [static deflections].

    **Returns:** a :class:`SubharmonicBranch` (`reached` False if the amplitude limit or
    `max_points` came first; the message says which).
    """
    sol = point.solution
    lo, hi = (omega_end, math.inf) if omega_end < point.omega else (-math.inf, omega_end)
    d = _engine.follow_period_doubled(GearSystem(model), _engine.PeriodDoublingPoint(point.omega, sol.z, point.multiplier,
                                                                                    ()),
                                      sol.harmonics, lo, hi, harmonics2=harmonics, samples2=samples,
                                      tolerance=tolerance, max_points=max_points, amplitude=amplitude,
                                      max_amplitude=max_amplitude, progress=False)
    return SubharmonicBranch(d.p, d.z, d.amplitude, d.hb, model, point, d.status == "reached range end", d.status,
                             d.message, d.mode)


# ============================================================================ backlash folds


def _dense_p2p_um(z, hb: HarmonicBalance, scale: float, samples: int = 2048) -> float:
    """Peak-to-peak DTE [um] of scaled unknowns `z` (displacement scale `scale` [m]) on a dense grid."""
    from ..engine import fourier

    x = np.asarray(z, dtype=float).reshape(hb.ndof, hb.block)[0]
    return float(np.ptp(fourier.synthesize(x, hb.harmonics, max(samples, 2 * hb.harmonics + 2)))) * 1e6 * scale


@dataclass(frozen=True)
class FoldCurve:
    """A frequency-response curve with its turning points.

    **Fields:** `branch`; `hb`; `model`; `speed_rpm` (path order); `dte_p2p_um`, `dte_rms_um`
    per point; `fold_speeds_rpm` (path order, after :func:`_merge_folds`); `raw_fold_speeds_rpm`
    (every fold the continuation located); `status`, `message`.
    """

    branch: Branch
    hb: HarmonicBalance
    model: object
    speed_rpm: np.ndarray
    dte_p2p_um: np.ndarray
    dte_rms_um: np.ndarray
    fold_speeds_rpm: np.ndarray
    status: Status
    message: str
    raw_fold_speeds_rpm: np.ndarray = None


def _merge_folds(speeds_rpm, rel: float = 1e-3) -> np.ndarray:
    """Merge runs of consecutive folds closer than `rel` (relative) in speed.

    With few AFT samples the contact-loss kinks make the path zigzag by a fraction of an rpm
    next to a genuine turning point (three folds at 10318.6, 10319.0, 10319.2 rpm): a run of an
    odd number of folds is one turning point (kept at its middle member), an even run is no net
    turn and is dropped.
    """
    out, run = [], []
    for f in np.asarray(speeds_rpm, dtype=float):
        if run and abs(f - run[-1]) > rel * abs(run[-1]):
            if len(run) % 2:
                out.append(run[len(run) // 2])
            run = []
        run.append(f)
    if len(run) % 2:
        out.append(run[len(run) // 2])
    return np.asarray(out)


def backlash_frc(model, rpm_start: float, rpm_stop: float, *, harmonics: int = 16, samples: int | None = None,
                 tolerance: float = 1e-9, max_points: int = 2000, step_rpm: float | None = None) -> FoldCurve:
    """Frequency-response curve of a model with backlash through both folds of its resonance
    (:func:`hbgear.gear.response.frequency_response` without stability; ``nu = 1``, `harmonics`,
    `samples` AFT samples, default ``max(512, 16 H)``: the contact-loss kinks alias at O(1/N));
    the located turning points, merged where aliasing makes the path zigzag
    (:func:`_merge_folds`), are `fold_speeds_rpm` (a softening contact-loss resonance has two).
    """
    from .response import frequency_response

    samples = samples or max(512, 16 * harmonics)
    curve = frequency_response(model, rpm_to_rad_s(rpm_start), rpm_to_rad_s(rpm_stop), harmonics=harmonics,
                               samples=samples, tolerance=tolerance, max_points=max_points,
                               step=None if step_rpm is None else rpm_to_rad_s(step_rpm), stability=False,
                               period_doubling=False, progress=False)
    branch, hb = curve.response.branch, curve.response.hb
    scale = float(GearSystem(model).displacement_scale)
    p2p = np.array([_dense_p2p_um(z, hb, scale) for z in branch.z])
    x = np.asarray(branch.z).reshape(len(branch), model.ndof, hb.block)[:, 0, 1:] * scale
    rms = 1e6 * np.sqrt(0.5 * np.sum(x**2, axis=1))
    raw = rad_s_to_rpm(np.asarray(branch.fold_p))
    return FoldCurve(branch, hb, model, rad_s_to_rpm(np.asarray(branch.p)), p2p, rms, _merge_folds(raw),
                     branch.status, branch.message, raw)


# ============================================================================ time-integration sweeps


def _final_state(response) -> np.ndarray:
    """``(q, q')`` at the start (mesh phase 0) of the last recorded steady mesh cycle."""
    starts = np.flatnonzero(np.asarray(response.s) == 0.0)
    i = int(starts[-1])
    return np.concatenate([response.q[:, i], response.qd[:, i]])


@dataclass(frozen=True)
class SweepResult:
    """One time-integration sweep: `speed_rpm` in the order run, `dte_p2p_um`, `dte_rms_um`,
    `period_cycles`, `cycles` integrated per speed, and the final `states` ``(q, q')``."""

    speed_rpm: np.ndarray
    dte_p2p_um: np.ndarray
    dte_rms_um: np.ndarray
    period_cycles: np.ndarray
    cycles: np.ndarray
    states: tuple


def ti_sweep(model, speeds_rpm, *, start_state=None, max_cycles: int = 3000, rtol: float = 1e-8,
             steady_tolerance: float = 1e-6, period_cycles=(1, 2)) -> SweepResult:
    """Time integration at each of `speeds_rpm` in turn, each started from the previous steady
    state (the first from `start_state`, or the quasi-static state)."""
    y = start_state
    rows = []
    for rpm in speeds_rpm:
        r = simulate(model, rpm_to_rad_s(float(rpm)), initial_state=y, max_cycles=max_cycles, rtol=rtol,
                           steady_tolerance=steady_tolerance, period_cycles=period_cycles)
        y = _final_state(r)
        rows.append((float(rpm), r.summary["dte_p2p_um"], r.summary["dte_rms_um"], r.period_cycles, r.cycles, y))
    cols = list(zip(*rows)) if rows else [()] * 6
    return SweepResult(np.array(cols[0]), np.array(cols[1]), np.array(cols[2]), np.array(cols[3], dtype=int),
                       np.array(cols[4], dtype=int), tuple(cols[5]))


@dataclass(frozen=True)
class JumpResult:
    """Jump speeds of time-integration sweeps.

    **Fields:** `up_rpm` (the jump met sweeping up: for a softening resonance the jump up at the
    upper fold), `down_rpm` (sweeping down), each the middle of its final bracket
    `up_bracket_rpm` / `down_bracket_rpm` (last speed on the old branch, first on the new);
    `up`, `down`: the coarse :class:`SweepResult` sweeps; `runs`: time integrations done.
    """

    up_rpm: float
    down_rpm: float
    up_bracket_rpm: tuple
    down_bracket_rpm: tuple
    up: SweepResult
    down: SweepResult
    runs: int


def _jump(sweep: SweepResult, threshold: float):
    """Index ``i`` of the largest relative p2p change between runs ``i`` and ``i+1`` (or None)."""
    p = sweep.dte_p2p_um
    if len(p) < 2:
        return None
    change = np.abs(np.diff(p)) / np.minimum(p[:-1], p[1:])
    i = int(np.argmax(change))
    return i if change[i] > threshold else None


def _refine(model, sweep: SweepResult, i: int, resolution_rpm: float, kwargs) -> tuple[tuple, int]:
    """Bisect the jump between runs ``i`` and ``i+1`` of `sweep`, always starting from the old branch."""
    a, b = float(sweep.speed_rpm[i]), float(sweep.speed_rpm[i + 1])
    pa, pb = float(sweep.dte_p2p_um[i]), float(sweep.dte_p2p_um[i + 1])
    ya = sweep.states[i]
    runs = 0
    while abs(b - a) > resolution_rpm:
        c = 0.5 * (a + b)
        r = simulate(model, rpm_to_rad_s(c), initial_state=ya, **kwargs)
        runs += 1
        pc = r.summary["dte_p2p_um"]
        if abs(pc - pa) < 0.5 * abs(pb - pa):  # still on the old branch
            a, pa, ya = c, pc, _final_state(r)
        else:
            b = c
    return (a, b), runs


def jump_speeds(
    model,
    rpm_low: float,
    rpm_high: float,
    step_rpm: float,
    *,
    resolution_rpm: float | None = None,
    threshold: float = 0.25,
    max_cycles: int = 3000,
    rtol: float = 1e-8,
    steady_tolerance: float = 1e-6,
) -> JumpResult:
    """Jump-up and jump-down speeds from time-integration sweeps up and down in speed.

    Sweeps `rpm_low` -> `rpm_high` and back in steps of `step_rpm` (each run from the previous
    steady state), finds in each the step with the largest relative change of the peak-to-peak
    DTE (it must exceed `threshold`), and bisects that step, restarting from the last state on
    the old branch, down to `resolution_rpm` (default ``step_rpm / 8``).

    **Raises:** :class:`~hbgear.errors.ConvergenceError` if a sweep shows no jump.
    """
    kwargs = dict(max_cycles=max_cycles, rtol=rtol, steady_tolerance=steady_tolerance)
    resolution = step_rpm / 8 if resolution_rpm is None else resolution_rpm
    n = int(math.ceil((rpm_high - rpm_low) / step_rpm - 1e-9))
    speeds = np.linspace(rpm_low, rpm_high, n + 1)
    up = ti_sweep(model, speeds, **kwargs)
    down = ti_sweep(model, speeds[::-1], start_state=up.states[-1], **kwargs)
    runs = 2 * len(speeds)
    out = []
    for name, sweep in (("up", up), ("down", down)):
        i = _jump(sweep, threshold)
        if i is None:
            raise ConvergenceError(
                f"the {name} sweep {sweep.speed_rpm[0]:.6g} -> {sweep.speed_rpm[-1]:.6g} rpm shows no jump "
                f"(largest relative change of the DTE peak-to-peak below {threshold:g}); widen the range"
            )
        bracket, k = _refine(model, sweep, i, resolution, kwargs)
        runs += k
        out.append(bracket)
    (ua, ub), (da, db) = out
    return JumpResult(0.5 * (ua + ub), 0.5 * (da + db), (ua, ub), (da, db), up, down, runs)
