r"""One periodic solution, and a frequency-response curve with its stability, for any periodic system.

:func:`solve` finds the periodic solution of a :class:`~hbgear.engine.system.PeriodicSystem` at
one parameter value by harmonic balance and Newton. :func:`frequency_response` follows it over a
parameter range by pseudo-arclength continuation (through folds), computes the Floquet
multipliers of every point (:func:`hbgear.engine.stability.branch_stability`), scans linear systems
for unstable zones between the points, locates the period doublings (multipliers leaving
through -1) and, when asked, follows the ``nu = 2`` branches born there
(:mod:`hbgear.engine.bifurcation`). Results are immutable: :class:`PeriodicSolution`,
:class:`FrequencyResponse`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np

from ..errors import ConvergenceError
from . import fourier
from .arrays import device_array
from .bifurcation import DoubledBranch, PeriodDoublingPoint, follow_period_doubled, locate_period_doublings
from .continuation import Branch, Status, continuation, solve_at_parameter, sweep_method
from .floquet import hill_multipliers, period_doubling
from .hb import HarmonicBalance
from .metric import continuation_functions
from .newton import NewtonResult, newton
from .prefetch import import_in_background
from .stability import BranchStability, branch_stability, unstable_zones
from .system import check_system

__all__ = ["PeriodicSolution", "FrequencyResponse", "DoubledBranch", "solve", "frequency_response", "default_samples",
           "newton_solve", "solution_multipliers", "synthesize"]


def default_samples(harmonics: int, nu: int = 1) -> int:
    """AFT samples per base period when none are given: ``max(1024, 4 H nu + 2)``, a multiple of ``nu``."""
    samples = max(1024, 4 * harmonics * nu + 2)
    return samples + samples % nu


@dataclass(frozen=True)
class PeriodicSolution:
    """A periodic solution found by harmonic balance.

    **Fields:** `system`; `parameter` ``p``; `harmonics` ``H``; `nu` (base frequency
    ``w_exc / nu``); `samples` ``N`` (AFT); `z` the scaled unknowns; `residual_norm` (max-norm of
    the scaled residual); `iterations` (Newton); `multipliers` (Floquet, over the base period,
    trivial ones dropped, largest modulus first; ``None`` if not computed).

    **Derived:** `hb` (the discretisation), `coefficients` ``(ndof, 2H+1)`` in SI (real basis
    ``[a_0, a_1, b_1, ...]`` on the base frequency), `extra` (a free coordinate's constant force),
    `base_frequency` [rad/s], :meth:`state_at`, :meth:`max_abs`.
    """

    system: object
    parameter: float
    harmonics: int
    nu: int
    samples: int
    z: np.ndarray
    residual_norm: float = 0.0
    iterations: int = 0
    multipliers: np.ndarray | None = None

    @cached_property
    def hb(self) -> HarmonicBalance:
        return HarmonicBalance(self.system.ndof, self.harmonics, self.nu, self.samples)

    @cached_property
    def _decoded(self):
        return self.hb.decode(self.system, self.z)

    @property
    def coefficients(self) -> np.ndarray:
        return self._decoded[0]

    @property
    def extra(self) -> float:
        return float(self._decoded[1])

    @property
    def base_frequency(self) -> float:
        return float(self.system.excitation_frequency(self.parameter)) / self.nu

    def state_at(self, base_fraction):
        """``(q, q')`` at fractions of the base period, shapes ``(ndof, n)`` [SI]."""
        tau = 2 * np.pi * np.asarray(base_fraction, dtype=float).ravel()
        k = np.arange(1, self.harmonics + 1)
        return synthesize(self.coefficients, self.base_frequency, np.cos(np.outer(k, tau)), np.sin(np.outer(k, tau)))

    def state_on_grid(self, points: int):
        """``(q, q')`` at the base-period fractions ``j / points``, ``j < points``, shapes
        ``(ndof, points)``: :meth:`state_at` on a uniform grid by FFT (``points >= 2H + 2``)."""
        if points < 2 * self.harmonics + 2:
            return self.state_at(np.arange(points) / points)
        velocity = fourier.differentiate(self.coefficients, self.harmonics, self.base_frequency)
        return tuple(fourier.synthesize(c, self.harmonics, points) for c in (self.coefficients, velocity))

    def max_abs(self, coordinate: int) -> float:
        """``max |q_i(t)|`` over one base period (on ``16 H`` uniform points, by FFT)."""
        q = fourier.synthesize(self.coefficients[coordinate], self.harmonics, 16 * self.harmonics)
        return float(np.max(np.abs(q)))

    def with_multipliers(self, multipliers) -> PeriodicSolution:
        from dataclasses import replace

        return replace(self, multipliers=None if multipliers is None else np.asarray(multipliers))


def synthesize(coefficients, base_frequency, cos, sin):
    """``(q, q')`` at the points of the basis ``cos, sin`` ``(H, n)`` from real coefficients
    ``(..., ndof, 2H+1)``: shapes ``(..., ndof, n)``; `base_frequency` broadcasts against them."""
    k = np.arange(1, cos.shape[0] + 1)
    c = np.asarray(coefficients, dtype=float)
    flat = c.reshape(-1, c.shape[-1])  # one matrix product for all points and coordinates
    a, b = flat[:, 1::2], flat[:, 2::2]
    basis = np.concatenate([cos, sin])
    q = flat[:, :1] + np.concatenate([a, b], axis=1) @ basis
    qd = np.concatenate([b * k, -a * k], axis=1) @ basis
    return q.reshape(c.shape[:-1] + (-1,)), base_frequency * qd.reshape(c.shape[:-1] + (-1,))


def newton_solve(hb: HarmonicBalance, system, p: float, z0, *, tolerance: float = 1e-9, max_iterations: int = 50,
                 prepared=None):
    """Damped Newton (:func:`hbgear.engine.newton.newton`) on the harmonic-balance residual at `p`.

    On the dense path the evaluation is the continuation's ``(R, dR/dz, dR/dp)`` with ``dR/dp``
    dropped (a start solution followed by a curve then compiles one Jacobian function, not two);
    on the structured path (many harmonics: the size decides,
    :attr:`~hbgear.engine.hb.HarmonicBalance.structured`) the matrix-free linearisation, its
    steps by GMRES (a linear system's to the tolerance at once: one step). Full steps are
    evaluated with the Jacobian (kept when taken, as they mostly are): the residual-only function
    is compiled only once a step is halved (a first solve of the relieved ISO pair at H = 48
    compiles one program of ~20 s instead of two).
    **Returns:** the :class:`~hbgear.engine.newton.NewtonResult`.
    """
    prepared = hb.prepare(system) if prepared is None else prepared

    def both(z):
        return hb.residual_and_linearization(device_array(z), p, system, prepared)

    def resid(z):
        return hb.residual(device_array(z), p, system, prepared)

    linear_rtol = 0.1 * tolerance if system.is_linear else None
    return newton(both, resid, np.asarray(z0, dtype=float), tolerance=tolerance, max_iterations=max_iterations,
                  linear_rtol=linear_rtol, jacobian_at_full_step=True)


def solve(system, parameter: float, *, harmonics: int, nu: int = 1, samples: int | None = None,
          tolerance: float = 1e-9, max_iterations: int = 50, z0=None, stability: bool = True) -> PeriodicSolution:
    """The periodic solution of `system` at `parameter` by harmonic balance (Newton from `z0`,
    default zero harmonics: one exact step for a linear system).

    **Arguments:** `harmonics` ``H``; `nu` (1, or 2 for half orders); `samples` AFT samples per
    base period (default :func:`default_samples`); `tolerance` on the scaled residual's max-norm;
    `z0` start unknowns (scaled, ``ndof (2H+1)``); `stability`: Floquet multipliers by Hill's
    method (exact monodromy for a linear system).

    **Raises:** :class:`~hbgear.errors.ConvergenceError` with the parameter, what was tried and the
    residual; ``ValueError`` / ``TypeError`` for a system that breaks the contract.
    """
    check_system(system, parameter)
    samples = default_samples(harmonics, nu) if samples is None else samples + samples % nu
    hb = HarmonicBalance(system.ndof, harmonics, nu, samples)
    z0 = np.zeros(hb.size) if z0 is None else np.asarray(z0, dtype=float)
    result = newton_solve(hb, system, float(parameter), z0, tolerance=tolerance,
                          max_iterations=3 if system.is_linear else max_iterations)
    if not result.converged:
        raise ConvergenceError(f"harmonic balance at p = {float(parameter):.9g} (H={harmonics}, nu={nu}, N={samples}): "
                               f"Newton from the given start, {result.iterations} iterations: residual "
                               f"{result.residual_norm:.3e} > tolerance {tolerance:.1e}")
    solution = PeriodicSolution(system, float(parameter), harmonics, nu, samples, np.asarray(result.z),
                                float(result.residual_norm), int(result.iterations))
    if not stability:
        return solution
    return solution.with_multipliers(solution_multipliers(hb, system, solution.z, float(parameter)))


def solution_multipliers(hb, system, z, p):
    """Floquet multipliers over the base period of one solution: exact monodromy where the system's
    linearization holds along it, else Hill's method where the discretisation is dense, and the
    variational equations on the structured path (many harmonics: Hill's matrices would be
    ``(size x size)`` and its eigenproblem ``O(size^3)``; the variational equations cost the same
    at any ``H``, the solution entering only through its state along the period)."""
    linear = system.linearization()
    if linear is not None and (linear is system or system.in_linear_regime(hb, z, p)):
        from .monodromy import multipliers_linear

        return np.asarray(multipliers_linear(linear, float(p))) ** hb.nu
    if hb.structured:
        from .monodromy import variational_multipliers

        return variational_multipliers(hb, system, z, float(p))
    return np.asarray(hill_multipliers(hb, z, float(p), system))


@dataclass(frozen=True)
class FrequencyResponse:
    """A frequency-response curve: the branch in path order, its stability, its bifurcations.

    **Fields:** `system`; `hb` (the ``nu`` discretisation of the branch); `branch` (the
    :class:`~hbgear.engine.continuation.Branch`: parameter, unknowns, kinds, residuals, status);
    `stability` (:class:`~hbgear.engine.stability.BranchStability` or ``None``); `unstable_zones`
    (linear systems: intervals from the exact scan, :func:`~hbgear.engine.stability.unstable_zones`);
    `period_doublings` (one dict per located -1 crossing: ``parameter``, ``multiplier``,
    ``bracket``, ``bracket_rows``, ``unstable_side``, ``status``, ``message``, ``branch``
    (index into `doubled` or ``None``)); `doubled` (the followed ``nu = 2`` branches,
    :class:`~hbgear.engine.bifurcation.DoubledBranch`, with `doubled_stability`); `timings_s`.

    **Derived (arrays in path order):** `parameter`, `z`, `coefficients` ``(points, size)`` in SI,
    `stable` (1/0, NaN where unknown), `max_abs_floquet`, `multipliers`, `folds` (fold parameters),
    :meth:`max_abs`.
    """

    system: object
    hb: HarmonicBalance
    branch: Branch
    stability: BranchStability | None = None
    unstable_zones: list = field(default_factory=list)
    period_doublings: list = field(default_factory=list)
    doubled: list = field(default_factory=list)
    doubled_stability: list = field(default_factory=list)
    timings_s: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.branch)

    @property
    def success(self) -> bool:
        return self.branch.success

    @property
    def status(self) -> Status:
        return self.branch.status

    @property
    def message(self) -> str:
        return self.branch.message

    @property
    def parameter(self) -> np.ndarray:
        return self.branch.p

    @property
    def z(self) -> np.ndarray:
        return self.branch.z

    @cached_property
    def coefficients(self) -> np.ndarray:
        return self.hb.decode(self.system, self.branch.z)[0].reshape(len(self.branch), -1)

    @property
    def stable(self) -> np.ndarray:
        return np.full(len(self), np.nan) if self.stability is None else self.stability.stable

    @property
    def max_abs_floquet(self) -> np.ndarray:
        return np.full(len(self), np.nan) if self.stability is None else self.stability.max_abs

    @property
    def multipliers(self) -> list:
        return [None] * len(self) if self.stability is None else self.stability.multipliers

    @property
    def folds(self) -> np.ndarray:
        """Parameters of the located folds (turning points)."""
        return self.branch.fold_p

    def max_abs(self, coordinate: int) -> np.ndarray:
        """``max |q_i(t)|`` over one base period at every point (on ``16 H`` uniform points each, by FFT)."""
        c = self.coefficients.reshape(len(self), self.system.ndof, -1)[:, coordinate]
        return np.max(np.abs(fourier.synthesize(c, self.hb.harmonics, 16 * self.hb.harmonics)), axis=-1)

    def solution(self, i: int) -> PeriodicSolution:
        """Point `i` as a :class:`PeriodicSolution`."""
        m = None if self.stability is None else self.stability.multipliers[i]
        return PeriodicSolution(self.system, float(self.branch.p[i]), self.hb.harmonics, self.hb.nu, self.hb.samples,
                                np.asarray(self.branch.z[i]), float(self.branch.residual[i]),
                                int(self.branch.iterations[i]), m)


def _follow(system, hb, p0, p1, z0, *, tolerance, max_points, max_iterations, step, progress, start):
    """The branch from `p0` to `p1`: Newton from `z0` in the compiled corrector; on a failed start
    the `start` callable (``p -> z``, e.g. a staged solve) gives a converged start point."""
    rj, r, fixed, sizes = continuation_functions(hb, system, p0)
    method = sweep_method(p0, p1, step)

    def run(z, iterations):
        z = np.asarray(z, dtype=float) if sizes is None else np.asarray(z, dtype=float) / sizes
        branch = continuation(rj, r, z, p0, p1, method, max_points=max_points, tolerance=tolerance,
                              progress=progress, args=fixed, start_iterations=iterations)
        return branch if sizes is None else replace(branch, z=branch.z * sizes)

    if z0 is not None:
        branch = run(z0, max_iterations)
        if branch.status != Status.START_FAILED or start is None:
            return branch
    if start is None:
        return run(np.zeros(hb.size), max_iterations)
    return run(start(p0), 10)


def corrector_solve(hb: HarmonicBalance, system, p: float, z0, *, tolerance: float = 1e-9,
                    max_iterations: int = 50, sizes_at=None) -> NewtonResult:
    """The solution at `p` by the compiled corrector of a curve of `system` (the program its
    continuation compiled: :func:`~hbgear.engine.continuation.solve_at_parameter`), in the unknowns
    of that curve (:func:`arclength_sizes` at `sizes_at`, default `p`: pass the curve's start to
    share its program); ``z`` of the result in `hb`'s unknowns."""
    rj, r, fixed, sizes = continuation_functions(hb, system, p if sizes_at is None else sizes_at)
    z0 = np.asarray(z0, dtype=float)
    result = solve_at_parameter(rj, r, z0 if sizes is None else z0 / sizes, float(p), args=fixed, tolerance=tolerance,
                                max_iterations=max_iterations)
    return result if sizes is None else result._replace(z=np.asarray(result.z) * sizes)


def _period_doubling_candidates(multipliers) -> tuple[list[int], np.ndarray]:
    """Indices ``i`` (and the flags) where the -1 flag (:func:`~hbgear.engine.floquet.period_doubling`) differs
    between points ``i`` and ``i+1`` (both known)."""
    flags = np.array([np.nan if m is None else float(period_doubling(m)) for m in multipliers])
    return [i for i in range(len(flags) - 1)
            if np.isfinite(flags[i]) and np.isfinite(flags[i + 1]) and flags[i] != flags[i + 1]], flags


def _locate_and_follow(system, hb, branch, multipliers, *, follow, tolerance, max_iterations, max_points,
                       p_range, progress, harmonics2=None, samples2=None):
    """The period-doubling records and the followed ``nu = 2`` branches of a ``nu = 1`` branch."""

    def solve_nu1(p, z0):  # the curve's own compiled corrector: nothing more to compile
        result = corrector_solve(hb, system, float(p), z0, tolerance=tolerance, max_iterations=max_iterations,
                                 sizes_at=branch.p[0])
        if not result.converged:
            raise ConvergenceError(f"nu = 1 solve at p = {p:.9g} for the period-doubling search: residual "
                                   f"{result.residual_norm:.3e}")
        return np.asarray(result.z)

    candidates, flags = _period_doubling_candidates(multipliers)
    t0 = time.perf_counter()
    located = locate_period_doublings(system, hb, solve_nu1, [(branch.p[i], branch.z[i], branch.p[i + 1],
                                                               branch.z[i + 1]) for i in candidates])
    share = (time.perf_counter() - t0) / max(len(candidates), 1)  # the crossings are located together
    records, doubled, ends = [], [], []
    for i, (point, why) in zip(candidates, located):
        t0 = time.perf_counter()
        pa, pb = float(branch.p[i]), float(branch.p[i + 1])
        rec = {"bracket": [pa, pb], "bracket_rows": [i, i + 1], "branch": None,
               "unstable_side": "below" if (flags[i] > flags[i + 1]) == (pa < pb) else "above"}
        if point is None:
            rec.update(status="not confirmed" if why.startswith("the multipliers") else "failed", message=why,
                       time_s=share + time.perf_counter() - t0)
            records.append(rec)
            continue
        rec.update(parameter=point.p, multiplier=point.multiplier)
        rec.update(_follow_record(system, point, hb, follow, ends, doubled, tolerance, max_points, p_range, progress,
                                  harmonics2, samples2))
        rec["time_s"] = share + time.perf_counter() - t0
        records.append(rec)
    return records, doubled


def _follow_record(system, point: PeriodDoublingPoint, hb, follow, ends, doubled, tolerance, max_points, p_range,
                   progress, harmonics2, samples2) -> dict:
    """Follow the ``nu = 2`` branch at `point` (when `follow` and not rejoined already); the record's
    status/message/branch index; appends to `doubled` and, if it reconnects, its end to `ends`."""
    if system.is_linear:
        return {"status": "not followed", "message": "linear model: the nu = 2 branch is vertical and unbounded at "
                "the crossing (a parametric instability), nothing to follow"}
    if not follow:
        return {"status": "not followed", "message": "nu = 2 branches not followed here"}
    if any(abs(e - point.p) <= 5e-3 * abs(point.p) for e in ends):
        return {"status": "joined", "message": "the nu = 2 branch of an earlier crossing rejoins the nu = 1 curve here; "
                "not followed twice"}
    try:
        result = follow_period_doubled(system, point, hb.harmonics, min(p_range), max(p_range),
                                       harmonics2=harmonics2 if harmonics2 else 2 * hb.harmonics,
                                       samples2=samples2 if samples2 else 2 * hb.samples, tolerance=tolerance,
                                       max_points=max_points, progress=progress)
    except Exception as exc:  # noqa: BLE001 -- reported, the nu = 1 curve is kept
        return {"status": "failed", "message": f"branch switching failed: {type(exc).__name__}: {exc}"}
    if result.status == "reconnected" and len(result.p):
        ends.append(float(result.p[-1]))
    doubled.append(result)
    return {"status": result.status, "message": result.message, "branch": len(doubled) - 1}


def frequency_response(system, parameter: tuple[float, float], *, harmonics: int, nu: int = 1,
                       samples: int | None = None, tolerance: float = 1e-9, max_iterations: int = 50,
                       max_points: int = 4000, step: float | None = None, z0=None, start=None,
                       stability: bool = True, zones: bool = True, period_doubling: str | bool = "locate",
                       progress=None, harmonics2: int | None = None, samples2: int | None = None) -> FrequencyResponse:
    """The frequency-response curve of `system` over ``parameter = (p_start, p_stop)`` (either may
    be the larger), by pseudo-arclength continuation through folds.

    **Arguments:** `harmonics`, `nu`, `samples` as for :func:`solve`; `max_points`; `step`: first
    parameter step (default: a quarter of the largest, 1/100 of the range); `z0`: start unknowns
    at ``p_start`` (default zero harmonics), corrected by Newton inside the compiled corrector;
    `start`: ``p -> z`` called when that fails (a staged solve); `stability`: Floquet
    multipliers at every point; `zones`: for a linear system, the exact scan for unstable zones
    between the points; `period_doubling`: ``False`` (not looked for), ``"locate"`` (the -1
    crossings are located and listed) or ``"follow"`` / ``True`` (and their ``nu = 2`` branches
    followed within the range, ``H2 = 2 H`` and twice the samples unless given); `progress`: a
    progress bar (``None``: only on a terminal).

    **Returns:** a :class:`FrequencyResponse`; a continuation that stops early is returned with its
    status and message (check ``.success``), never silently as complete.
    """
    p0, p1 = float(parameter[0]), float(parameter[1])
    if not p0 != p1:
        raise ValueError(f"parameter range ({p0}, {p1}): two different values")
    check_system(system, p0)
    samples = default_samples(harmonics, nu) if samples is None else samples + samples % nu
    hb = HarmonicBalance(system.ndof, harmonics, nu, samples)
    clock = time.perf_counter
    t0 = clock()
    if period_doubling and stability and nu == 1 and not system.is_linear:
        import_in_background("scipy.integrate")  # the search's variational monodromy, during the curve
    branch = _follow(system, hb, p0, p1, z0, tolerance=tolerance, max_points=max_points,
                     max_iterations=max_iterations, step=step, progress=progress, start=start)
    t1 = clock()
    stab = (branch_stability(hb, system, branch.p, branch.z, folds=branch.folds, progress=progress)
            if stability and len(branch) else None)
    t2 = clock()
    found_zones = unstable_zones(system, branch.p) if zones and stability and system.is_linear and len(branch) > 1 else []
    t3 = clock()
    records, doubled, doubled_stab = [], [], []
    if period_doubling and stab is not None and nu == 1:
        records, doubled = _locate_and_follow(
            system, hb, branch, stab.multipliers, follow=period_doubling in (True, "follow"), tolerance=tolerance,
            max_iterations=max_iterations, max_points=max_points, p_range=(p0, p1), progress=progress,
            harmonics2=harmonics2, samples2=samples2)
        doubled_stab = [branch_stability(d.hb, system, d.p, d.z, progress=progress, label="Floquet multipliers (nu = 2)")
                        for d in doubled]
    t4 = clock()
    timings = {"compile_and_start_point": branch.start_seconds, "continuation": t1 - t0 - branch.start_seconds,
               "stability": t2 - t1, "zones": t3 - t2, "period_doubling": t4 - t3}
    return FrequencyResponse(system, hb, branch, stab, found_zones, records, doubled, doubled_stab, timings)

