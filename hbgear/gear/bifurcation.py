r"""Bifurcations of the gear pair's periodic steady states (MODEL.md sections 5, 6 and 8).

Three tools, each checked against time integration in ``tests/test_bifurcation.py`` and
``validation/``:

- **Period doubling -> the** ``nu = 2`` **branch.** Where a real Floquet multiplier of the
  ``nu = 1`` solution leaves through -1 (the parametric tongue around ``w_m = 2 w_n``), the
  period-doubled branch is born. In the ``nu = 2`` basis (base frequency ``w_m / 2``) the
  ``nu = 1`` solution is embedded exactly (mesh order ``k`` -> base index ``2k``,
  :func:`embed_subharmonic`), and because all coefficients of the linearisation are
  ``T_m``-periodic the ``nu = 2`` Jacobian there splits into an even block (mesh orders) and an
  odd block (half orders). The Floquet eigenfunction of the multiplier -1 is the null vector of
  the odd block (:func:`half_order_mode`). :func:`locate_period_doubling` refines the crossing
  between two speeds, :func:`switch_to_period_doubled` solves the bordered system
  ``R(z, p) = 0``, ``phi . (z - z_*) = a`` (a point of the new branch at a small half-order
  amplitude ``a``; Newton from ``z_* + a phi`` at fixed speed would fall back onto the
  ``nu = 1`` solution, which also solves the ``nu = 2`` equations), and
  :func:`continue_period_doubled` follows the new branch with
  :func:`hbgear.engine.continuation.continuation`, around its fold if it is born subcritical.
  :func:`solve_period_doubled` converges one ``nu = 2`` solution from a given start with
  :func:`hbgear.gear.solve.solve_periodic` and rejects a collapse back onto the ``nu = 1`` solution.
- **Backlash folds** (:func:`backlash_frc`): the frequency-response curve by arclength
  continuation through both turning points of the softening contact-loss resonance, with the
  fold speeds.
- **Time-integration sweeps** (:func:`ti_sweep`, :func:`jump_speeds`): the speed is stepped
  and every run starts from the previous run's steady state, so the hysteresis of the jumps
  shows; the jump speeds are bracketed by bisection.

!!! note
    :func:`hbgear.gear.simulate.simulate` always starts from the quasi-static state. Until it takes
    an initial state, the sweeps call it through :func:`_simulate_from`, which substitutes the
    start state for the duration of one call (not thread-safe: one sweep per process at a time).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np
import scipy.linalg

from . import simulate as _simulate_module
from ..engine.continuation import Branch, PseudoArclength, Status, continuation, illinois
from ..errors import ConvergenceError
from ..engine.hb import HarmonicBalance
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
    "switch_to_period_doubled",
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


# ============================================================================ nu=1 -> nu=2


def embed_subharmonic(z, ndof: int, harmonics: int, harmonics_to: int | None = None, factor: int = 2) -> np.ndarray:
    """The same waveform in a basis on ``1/factor`` of the base frequency.

    Per coordinate ``[a_0, a_1, b_1, ..., a_H, b_H]`` on ``w`` -> ``[a_0, ..., a_H2, b_H2]`` on
    ``w / factor``: harmonic ``k`` goes to index ``factor k``, the others are zero. Exact (the
    waveform is unchanged) when ``harmonics_to >= factor * harmonics`` (the default); harmonics
    above ``harmonics_to`` are dropped otherwise. Works on scaled unknowns ``z`` (the mean slot,
    which may hold the reaction force, is carried over as it is).

    **Arguments:** `z`: shape ``(ndof * (2H+1),)``; `ndof`; `harmonics` ``H``; `harmonics_to`
    ``H2`` (default ``factor H``); `factor`: ``nu_to / nu_from`` (2 for ``nu = 1 -> 2``).

    **Returns:** shape ``(ndof * (2 H2 + 1),)``.
    """
    if factor < 1:
        raise ValueError(f"factor must be >= 1, got {factor}")
    h2 = factor * harmonics if harmonics_to is None else int(harmonics_to)
    src = np.asarray(z, dtype=float).reshape(ndof, 2 * harmonics + 1)
    out = np.zeros((ndof, 2 * h2 + 1))
    out[:, 0] = src[:, 0]
    k = np.arange(1, harmonics + 1)
    m = factor * k
    keep = m <= h2
    out[:, 2 * m[keep] - 1] = src[:, 2 * k[keep] - 1]
    out[:, 2 * m[keep]] = src[:, 2 * k[keep]]
    return out.ravel()


def half_order_indices(ndof: int, harmonics: int) -> np.ndarray:
    """Positions of the odd base harmonics (half mesh orders for ``nu = 2``) in ``z``."""
    block = 2 * harmonics + 1
    odd = np.arange(1, harmonics + 1, 2)
    per = np.sort(np.concatenate([2 * odd - 1, 2 * odd]))
    return (np.arange(ndof)[:, None] * block + per[None]).ravel()


def half_order_share(z, ndof: int, harmonics: int) -> float:
    """RMS of the half-order DTE harmonics over the RMS of all DTE harmonics (nu=2 ``z``)."""
    x = np.asarray(z, dtype=float).reshape(ndof, 2 * harmonics + 1)[0, 1:]
    odd = half_order_indices(1, harmonics) - 1
    total = float(np.sqrt(np.sum(x**2)))
    return float(np.sqrt(np.sum(x[odd] ** 2))) / total if total > 0 else 0.0


def half_order_mode(hb2: HarmonicBalance, z2, p: float, system) -> tuple[np.ndarray, float]:
    """The half-order (period-doubling) Floquet mode at an embedded ``nu = 1`` solution.

    The ``nu = 2`` Jacobian at a ``T_m``-periodic solution maps half orders to half orders;
    its odd block is singular exactly where a multiplier (per mesh period) is -1, and its null
    vector is the Fourier series of that Floquet eigenfunction. Away from the crossing the
    smallest right singular vector is returned.

    **Returns:** ``(phi, sigma)``: unit vector of size ``hb2.size`` (zero on the mesh orders),
    and the smallest singular value of the odd block relative to its largest.
    """
    if hb2.nu != 2:
        raise ValueError(f"half_order_mode needs a nu = 2 discretisation, got nu = {hb2.nu}")
    _, jac = hb2.residual_and_jacobian(jnp.asarray(z2), float(p), system)
    idx = half_order_indices(hb2.ndof, hb2.harmonics)
    block = np.asarray(jac, dtype=float)[np.ix_(idx, idx)]
    _, s, vt = np.linalg.svd(block)
    phi = np.zeros(hb2.size)
    phi[idx] = vt[-1]
    # a sign convention: the largest component positive
    if phi[np.argmax(np.abs(phi))] < 0:
        phi = -phi
    return phi, float(s[-1] / s[0])


# ============================================================================ locating the -1 crossing


class PeriodDoublingPoint(NamedTuple):
    """A located period doubling: speed `omega` [rad/s] (`speed_rpm`), the ``nu = 1`` solution
    there, the real multiplier nearest -1 (per mesh period) and the speed bracket it came from."""

    omega: float
    speed_rpm: float
    solution: PeriodicSolution
    multiplier: float
    bracket_rpm: tuple


def period_doubling_multiplier(model, solution: PeriodicSolution) -> float:
    """The most negative real Floquet multiplier per mesh period (``nan`` if none is real negative).

    Exact monodromy for linear models (:func:`hbgear.gear.monodromy.multipliers_linear`), the
    variational equations along the ``nu = 1`` solution otherwise
    (:func:`hbgear.gear.monodromy.monodromy_variational`). Hill's method is not used here: with a
    few harmonics its selection of the real negative multiplier (whose exponents sit at
    half-integer harmonic centres) is not reliable enough to bracket the crossing.
    """
    from ..engine.floquet import most_negative_real
    from .monodromy import monodromy_variational, multipliers_linear

    if solution.nu != 1:
        raise ValueError("period_doubling_multiplier needs a nu = 1 solution")
    if model.is_linear:
        mult = np.asarray(multipliers_linear(model, float(solution.omega_pinion)))
    else:
        phi = monodromy_variational(model, solution, float(solution.omega_pinion))
        mult = np.linalg.eigvals(phi)
    return most_negative_real(mult)


def locate_period_doubling(
    model,
    omega_a: float,
    omega_b: float,
    *,
    harmonics: int = 16,
    samples: int | None = None,
    tolerance: float = 1e-9,
    speed_tolerance: float = 1e-6,
    max_steps: int = 40,
) -> PeriodDoublingPoint:
    r"""The speed between `omega_a` and `omega_b` [rad/s] where a multiplier crosses -1.

    The two speeds must bracket the crossing (``mu + 1`` of the most negative real multiplier
    changes sign). Illinois regula falsi on ``g = mu + 1``, each ``nu = 1`` solution started
    from the previous one, until the bracket is below ``speed_tolerance`` relative.

    **Raises:** `ValueError` if the speeds do not bracket a crossing.
    """
    z_prev = None

    def g(omega):
        nonlocal z_prev
        sol = solve_periodic(model, omega, harmonics=harmonics, nu=1, samples=samples, tolerance=tolerance, z0=z_prev)
        z_prev = sol.z
        mu = period_doubling_multiplier(model, sol)
        return (mu + 1.0 if np.isfinite(mu) else 1.0), (sol, mu)

    (ga, da), (gb, db) = g(omega_a), g(omega_b)
    if ga * gb > 0:
        raise ValueError(
            f"{rad_s_to_rpm(omega_a):.6g} and {rad_s_to_rpm(omega_b):.6g} rpm do not bracket a multiplier "
            f"crossing -1 (most negative real multipliers {da[1]:.6g}, {db[1]:.6g})"
        )
    a, b = float(omega_a), float(omega_b)
    (omega, (sol, mu), _), _ = illinois(g, a, ga, b, gb, (a, da, ga) if abs(ga) < abs(gb) else (b, db, gb),
                                       speed_tolerance, max_steps)
    return PeriodDoublingPoint(
        float(omega), rad_s_to_rpm(float(omega)), sol, float(mu), (rad_s_to_rpm(omega_a), rad_s_to_rpm(omega_b))
    )


# ============================================================================ branch switching


def _nu2_problem(model, harmonics2, samples2):
    samples2 = samples2 or max(256, 8 * harmonics2)
    samples2 += samples2 % 2
    return HarmonicBalance(model.ndof, harmonics2, 2, samples2), GearSystem(model)


def switch_to_period_doubled(
    model,
    point: PeriodDoublingPoint,
    *,
    harmonics: int | None = None,
    samples: int | None = None,
    amplitude: float = 0.05,
    tolerance: float = 1e-9,
    max_iterations: int = 30,
):
    r"""A point of the period-doubled branch next to the bifurcation `point`.

    Embeds the ``nu = 1`` solution (:func:`embed_subharmonic`), takes the half-order Floquet
    mode ``phi`` there (:func:`half_order_mode`) and solves by Newton the bordered system

    $$R_2(z, p) = 0, \qquad \phi \cdot (z - z_*) = a$$

    for ``(z, p)`` from ``(z_* + a phi, p_*)``: the speed is free, so the solution is on the new
    branch (at half-order amplitude `amplitude`, in static deflections), not the old one.

    **Arguments:** `harmonics`: ``H2`` of the ``nu = 2`` basis (default ``2 H``); `samples`: its
    AFT samples (default ``max(256, 8 H2)``).

    **Returns:** ``(z, omega, hb2, phi)``.

    **Raises:** :class:`~hbgear.errors.ConvergenceError` if the bordered Newton fails.
    """
    sol = point.solution
    h2 = 2 * sol.harmonics if harmonics is None else int(harmonics)
    hb2, system = _nu2_problem(model, h2, samples)
    z_star = embed_subharmonic(sol.z, model.ndof, sol.harmonics, h2)
    p_star = float(point.omega)
    phi, _ = half_order_mode(hb2, z_star, p_star, system)
    scale = p_star
    y = np.append(z_star + amplitude * phi, 1.0)
    target = float(phi @ z_star) + amplitude

    def evaluate(y):
        r, jz, jp = hb2.residual_and_jacobians(jnp.asarray(y[:-1]), float(y[-1] * scale), system)
        r = np.append(np.asarray(r, dtype=float), phi @ y[:-1] - target)
        jac = np.vstack([np.hstack([np.asarray(jz), scale * np.asarray(jp).reshape(-1, 1)]), np.append(phi, 0.0)])
        return r, jac

    r, jac = evaluate(y)
    norm = float(np.max(np.abs(r)))
    for _ in range(max_iterations):
        if norm <= tolerance:
            break
        step = scipy.linalg.solve(jac, -r)
        alpha = 1.0
        while True:
            trial = y + alpha * step
            r_t, jac_t = evaluate(trial)
            norm_t = float(np.max(np.abs(r_t)))
            if (np.isfinite(norm_t) and norm_t < (1 - 1e-4 * alpha) * norm) or alpha < 1 / 64:
                break
            alpha *= 0.5
        y, r, jac, norm = trial, r_t, jac_t, norm_t
    if not norm <= tolerance:
        raise ConvergenceError(
            f"branch switching at the period doubling {point.speed_rpm:.6g} rpm (H2={h2}, nu=2): bordered "
            f"Newton from the embedded solution + {amplitude:g} x half-order mode reached max|R| = {norm:.3e} "
            f"> {tolerance:.1e}; try a smaller amplitude"
        )
    return y[:-1], float(y[-1] * scale), hb2, phi


def solve_period_doubled(
    model,
    omega: float,
    z0,
    *,
    harmonics: int,
    samples: int | None = None,
    tolerance: float = 1e-9,
    max_iterations: int = 50,
    min_share: float = 1e-3,
) -> PeriodicSolution:
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
            "(switch_to_period_doubled / continue_period_doubled)"
        )
    return sol


@dataclass(frozen=True)
class SubharmonicBranch:
    """A continued ``nu = 2`` branch, in path order from the bifurcation.

    **Fields:** `omega` (n,) pinion speeds [rad/s]; `z` (n, size) scaled unknowns of `hb` (the
    ``nu = 2`` discretisation); `amplitude` (n,) the half-order amplitude ``phi . (z - z_*)``
    [static deflections]; `model`; `bifurcation` (:class:`PeriodDoublingPoint`); `reached`
    (the last point is solved exactly at the requested end speed); `status`, `message` (of the
    last continuation leg); `mode` ``phi``.
    """

    omega: np.ndarray
    z: np.ndarray
    amplitude: np.ndarray
    hb: HarmonicBalance
    model: object
    bifurcation: PeriodDoublingPoint
    reached: bool
    status: Status
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
        turns = np.flatnonzero(d[:-1] * d[1:] < 0) + 1
        return rad_s_to_rpm(w[turns])


def amplitude_residuals(hb2, system, w_star: float, phi, offset: float):
    """Residuals for continuing a nu=2 branch in its half-order amplitude ``a``.

    Unknowns ``y = (z, w / w_star)``; equations ``R(z; w) = 0`` and ``phi . z - offset = a``.
    **Returns:** ``(both, resid)``: ``(y, a) -> (R, dR/dy, dR/da)`` and ``(y, a) -> R``.
    """

    def both(y, a):
        r, jz, jp = hb2.residual_and_jacobians(jnp.asarray(y[:-1]), float(y[-1] * w_star), system)
        r = np.append(np.asarray(r, dtype=float), phi @ y[:-1] - offset - a)
        top = np.hstack([np.asarray(jz, dtype=float), w_star * np.asarray(jp, dtype=float).reshape(-1, 1)])
        jac = np.vstack([top, np.append(phi, 0.0)])
        jpar = np.zeros(len(r))
        jpar[-1] = -1.0
        return r, jac, jpar

    def resid(y, a):
        r = hb2.residual(jnp.asarray(y[:-1]), float(y[-1] * w_star), system)
        return np.append(np.asarray(r, dtype=float), phi @ y[:-1] - offset - a)

    return both, resid


def continue_period_doubled(
    model,
    point: PeriodDoublingPoint,
    omega_end: float,
    *,
    harmonics: int | None = None,
    samples: int | None = None,
    amplitude: float = 0.02,
    max_amplitude: float = 100.0,
    tolerance: float = 1e-9,
    max_points: int = 400,
) -> SubharmonicBranch:
    r"""Follow the period-doubled branch born at `point` until it reaches the speed `omega_end`.

    The branch is continued in its half-order amplitude ``a = phi . (z - z_*)`` (in static
    deflections), from `amplitude` up to at most `max_amplitude`, with the speed as an unknown:

    $$R_2(z, \Omega) = 0, \qquad \phi \cdot (z - z_*) = a.$$

    This parametrisation is regular at the bifurcation whatever the branch does there: a model
    that is linear until the teeth separate (backlash) has a *vertical* branch (any amplitude
    at ``Omega_*``) until contact is lost, then bends; a branch may also be born away from
    `omega_end` and fold back. Once the speed passes `omega_end` the last leg is an ordinary
    arclength continuation in speed that stops exactly at `omega_end`.

    **Returns:** a :class:`SubharmonicBranch` (`reached` False if the amplitude limit or
    `max_points` came first; the message says which).
    """
    from ..engine.continuation import sweep_method
    from ..engine.hb import residual_functions

    sol = point.solution
    h2 = 2 * sol.harmonics if harmonics is None else int(harmonics)
    hb2, system = _nu2_problem(model, h2, samples)
    z_star = embed_subharmonic(sol.z, model.ndof, sol.harmonics, h2)
    w_star = float(point.omega)
    phi, _ = half_order_mode(hb2, z_star, w_star, system)
    offset = float(phi @ z_star)
    sign = 1.0 if omega_end > w_star else -1.0

    both, resid = amplitude_residuals(hb2, system, w_star, phi, offset)

    def stop(a, w):
        if (w[-1] * w_star - omega_end) * sign >= 0:
            return True
        return False

    method = PseudoArclength(ds=0.02, ds_min=1e-8, ds_max=0.25, max_angle_deg=5.0, parameter_scale=max_amplitude)
    w0 = np.append(z_star + amplitude * phi, 1.0)
    leg = continuation(both, resid, w0, amplitude, max_amplitude, method, max_points=max_points, tolerance=tolerance,
                       callback=stop)
    omega = np.asarray(leg.z)[:, -1] * w_star
    zs = np.asarray(leg.z)[:, :-1]
    amp = np.asarray(leg.p)
    crossed = np.flatnonzero((omega - omega_end) * sign >= 0)
    if not crossed.size:
        message = (f"the period-doubled branch from {point.speed_rpm:.6g} rpm did not reach "
                   f"{rad_s_to_rpm(omega_end):.6g} rpm up to half-order amplitude {amp[-1]:.3g} "
                   f"({leg.status.name}: {leg.message})")
        return SubharmonicBranch(omega, zs, amp, hb2, model, point, False, leg.status, message, phi)
    k = int(crossed[0])
    both_p, resid_p, fixed = residual_functions(hb2, system)
    start = max(k - 1, 0)
    last = continuation(both_p, resid_p, zs[start], float(omega[start]), omega_end,
                        sweep_method(w_star, omega_end), max_points=max_points, tolerance=tolerance, args=fixed)
    z_last = np.asarray(last.z)
    amp_last = z_last @ phi - offset
    omega = np.concatenate([omega[: start + 1], np.asarray(last.p)[1:]])
    zs = np.concatenate([zs[: start + 1], z_last[1:]])
    amp = np.concatenate([amp[: start + 1], amp_last[1:]])
    return SubharmonicBranch(omega, zs, amp, hb2, model, point, last.success, last.status, last.message, phi)


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


def backlash_frc(
    model,
    rpm_start: float,
    rpm_stop: float,
    *,
    harmonics: int = 16,
    samples: int | None = None,
    tolerance: float = 1e-9,
    max_points: int = 2000,
    step_rpm: float | None = None,
) -> FoldCurve:
    """Frequency-response curve of a model with backlash through both folds of its resonance.

    Arclength continuation in speed from `rpm_start` to `rpm_stop` (``nu = 1``, `harmonics`,
    `samples` AFT samples, default ``max(512, 16 H)``: the contact-loss kinks alias at O(1/N));
    the turning points located by the continuation are returned as `fold_speeds_rpm` (a
    softening contact-loss resonance has two: where the curve turns back and where it turns
    forward again).
    """
    from ..engine.continuation import sweep_method
    from ..engine.hb import residual_functions

    samples = samples or max(512, 16 * harmonics)
    w0, w1 = rpm_to_rad_s(rpm_start), rpm_to_rad_s(rpm_stop)
    start = solve_periodic(model, w0, harmonics=harmonics, samples=samples, tolerance=tolerance)
    hb = HarmonicBalance(model.ndof, harmonics, 1, samples)
    both, resid, fixed = residual_functions(hb, GearSystem(model))
    method = sweep_method(w0, w1, None if step_rpm is None else rpm_to_rad_s(step_rpm))
    branch = continuation(both, resid, start.z, w0, w1, method, max_points=max_points, tolerance=tolerance,
                          args=fixed)
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


def _simulate_from(model, omega, y0, **kwargs):
    return _simulate_module.simulate(model, omega, initial_state=y0, **kwargs)


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
        r = _simulate_from(model, rpm_to_rad_s(float(rpm)), y, max_cycles=max_cycles, rtol=rtol,
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
        r = _simulate_from(model, rpm_to_rad_s(c), ya, **kwargs)
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
