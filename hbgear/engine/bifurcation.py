r"""Period doubling: locate the -1 crossing on a branch, switch to the ``nu = 2`` branch, follow it.

Where a real Floquet multiplier of a ``nu = 1`` solution leaves the unit circle through -1, the
period-doubled branch is born (MODEL.md section 6). In the ``nu = 2`` basis (base frequency
``w_exc / 2``) the ``nu = 1`` solution is embedded exactly (harmonic ``k`` -> base index ``2k``,
:func:`embed_subharmonic`); all coefficients of the linearisation there are periodic in the
excitation period, so the ``nu = 2`` Jacobian splits into an even block and an odd block (half
orders), and the Floquet eigenfunction of the multiplier -1 is the null vector of the odd block
(:func:`half_order_mode`).

- :func:`locate_period_doubling` -- the one locator: the crossing between two branch points, by
  Illinois regula falsi on ``mu + 1`` of the most negative real multiplier from exact or
  variational monodromy (:func:`exact_negative_multiplier`); all crossings of a branch in step
  (:func:`locate_period_doublings`), their multipliers in one batch per step.
- :func:`follow_period_doubled` -- the one follower: continuation in the half-order amplitude
  ``a = phi . (z - z_*)`` with the parameter as an unknown (regular at the bifurcation whether the
  branch is vertical, super- or subcritical), then an arclength leg in the parameter that stops
  exactly at the end of the range.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Callable, NamedTuple

import numpy as np

from .arrays import device_array
from .continuation import PseudoArclength, Status, continuation, sweep_method
from .continuation.folds import IllinoisBracket
from .floquet import most_negative_real
from .hb import HarmonicBalance
from .metric import arclength_sizes, continuation_functions
from .monodromy import monodromy_variational, multipliers_linear, state_synthesis

__all__ = [
    "PeriodDoublingPoint",
    "DoubledBranch",
    "amplitude_residuals",
    "embed_subharmonic",
    "exact_negative_multiplier",
    "exact_negative_multipliers",
    "follow_period_doubled",
    "half_order_indices",
    "half_order_mode",
    "half_order_share",
    "locate_period_doubling",
    "locate_period_doublings",
]


def embed_subharmonic(z, ndof: int, harmonics: int, harmonics_to: int | None = None, factor: int = 2) -> np.ndarray:
    """The same waveform in a basis on ``1/factor`` of the base frequency.

    Per coordinate ``[a_0, a_1, b_1, ..., a_H, b_H]`` on ``w`` -> ``[a_0, ..., a_H2, b_H2]`` on
    ``w / factor``: harmonic ``k`` goes to index ``factor k``, the others are zero. Exact (the
    waveform is unchanged) when ``harmonics_to >= factor * harmonics`` (the default); harmonics
    above ``harmonics_to`` are dropped otherwise. Works on scaled unknowns ``z`` (the mean slot,
    which may hold a free coordinate's force unknown, is carried over as it is).

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
    """Positions of the odd base harmonics (half orders for ``nu = 2``) in ``z``."""
    block = 2 * harmonics + 1
    odd = np.arange(1, harmonics + 1, 2)
    per = np.sort(np.concatenate([2 * odd - 1, 2 * odd]))
    return (np.arange(ndof)[:, None] * block + per[None]).ravel()


def half_order_share(z, ndof: int, harmonics: int) -> float:
    """RMS of the half-order harmonics of coordinate 0 over the RMS of all its harmonics (``nu = 2`` ``z``)."""
    x = np.asarray(z, dtype=float).reshape(ndof, 2 * harmonics + 1)[0, 1:]
    odd = half_order_indices(1, harmonics) - 1
    total = float(np.sqrt(np.sum(x**2)))
    return float(np.sqrt(np.sum(x[odd] ** 2))) / total if total > 0 else 0.0


def half_order_mode(hb2: HarmonicBalance, z2, p: float, system) -> tuple[np.ndarray, float]:
    """The half-order (period-doubling) Floquet mode at an embedded ``nu = 1`` solution.

    The ``nu = 2`` Jacobian at a solution periodic in the excitation period maps half orders to
    half orders; its odd block is singular exactly where a multiplier (per excitation period) is
    -1, and its null vector is the Fourier series of that Floquet eigenfunction. Away from the
    crossing the smallest right singular vector is returned.

    **Returns:** ``(phi, sigma)``: unit vector of size ``hb2.size`` (zero on the whole orders),
    and the smallest singular value of the odd block relative to its largest.
    """
    if hb2.nu != 2:
        raise ValueError(f"half_order_mode needs a nu = 2 discretisation, got nu = {hb2.nu}")
    _, jac = hb2.residual_and_jacobian(device_array(z2), float(p), system)
    idx = half_order_indices(hb2.ndof, hb2.harmonics)
    _, s, vt = np.linalg.svd(np.asarray(jac, dtype=float)[np.ix_(idx, idx)])
    phi = np.zeros(hb2.size)
    phi[idx] = vt[-1]
    if phi[np.argmax(np.abs(phi))] < 0:  # a sign convention: the largest component positive
        phi = -phi
    return phi, float(s[-1] / s[0])


def amplitude_residuals(hb2, system, p_star: float, phi, offset: float, sizes=None):
    """Residuals for continuing a ``nu = 2`` branch in its half-order amplitude ``a``.

    Unknowns ``y = (z / sizes, p / p_star)`` (`sizes`: :func:`~hbgear.engine.metric.arclength_sizes`
    of `hb2`, ``None`` for all 1); equations ``R(z; p) = 0`` and ``phi . z - offset = a``.
    **Returns:** ``(both, resid)``: ``(y, a) -> (R, dR/dy, dR/da)`` and ``(y, a) -> R``.
    """
    scale = np.ones(hb2.size) if sizes is None else np.asarray(sizes, dtype=float)
    phi_y = np.asarray(phi, dtype=float) * scale  # d(phi . z)/d(z / sizes)

    def both(y, a):
        z = y[:-1] * scale
        r, jz, jp = hb2.residual_and_jacobians(device_array(z), float(y[-1] * p_star), system)
        r = np.append(np.asarray(r, dtype=float), phi @ z - offset - a)
        top = np.hstack([np.asarray(jz, dtype=float) * scale[None, :], p_star * np.asarray(jp, dtype=float).reshape(-1, 1)])
        jpar = np.zeros(len(r))
        jpar[-1] = -1.0
        return r, np.vstack([top, np.append(phi_y, 0.0)]), jpar

    def resid(y, a):
        z = y[:-1] * scale
        r = hb2.residual(device_array(z), float(y[-1] * p_star), system)
        return np.append(np.asarray(r, dtype=float), phi @ z - offset - a)

    return both, resid


# ============================================================================ locating the crossing


class PeriodDoublingPoint(NamedTuple):
    """A located period doubling: the parameter `p`, the ``nu = 1`` unknowns `z` there (of the
    branch's discretisation), the real multiplier nearest -1 (per excitation period) and the
    parameter bracket ``(p_a, p_b)`` it was found in."""

    p: float
    z: np.ndarray
    multiplier: float
    bracket: tuple


def exact_negative_multipliers(system, hb: HarmonicBalance, zs, ps) -> np.ndarray:
    """:func:`exact_negative_multiplier` at the points ``(zs[i], ps[i])``: the ones where the
    system's linearization holds by exact monodromy, the others by one batched integration of
    their variational equations (:func:`~hbgear.engine.monodromy.monodromy_variational`)."""
    if hb.nu != 1:
        raise ValueError("exact_negative_multiplier needs a nu = 1 solution")
    ps = np.atleast_1d(np.asarray(ps, dtype=float))
    out = np.full(len(ps), np.nan)
    linear = system.linearization()
    rest = []
    for i, (z, p) in enumerate(zip(zs, ps)):
        if linear is not None and (linear is system or system.in_linear_regime(hb, z, p)):  # (z unused if linear)
            out[i] = most_negative_real(multipliers_linear(linear, float(p)))
        else:
            rest.append(i)
    if rest:
        coefficients = np.stack([hb.decode(system, zs[i])[0] for i in rest])
        base = np.array([float(hb.base_frequency(system, ps[i])) for i in rest])
        state = state_synthesis(coefficients, hb.harmonics, base)
        phi = monodromy_variational(system, ps[rest], state, 1, rtol=VARIATIONAL_RTOL)
        out[rest] = [most_negative_real(m) for m in np.linalg.eigvals(phi)]
    return out


def exact_negative_multiplier(system, hb: HarmonicBalance, z, p) -> float:
    """The most negative real Floquet multiplier per excitation period of the ``nu = 1`` solution
    `z` at `p` (``nan`` if none): exact monodromy where the system's linearization holds along it,
    the variational equations otherwise. Hill's method is not used here: with a few harmonics
    its selection of a real negative multiplier (exponents at half-integer harmonic centres) is
    not reliable enough to bracket the crossing."""
    return float(exact_negative_multipliers(system, hb, [np.asarray(z)], [p])[0])


#: ``rtol`` of the variational monodromy (DOP853) of the exact multipliers (per member of a batch).
VARIATIONAL_RTOL = 1e-10

#: A failed or non-finite multiplier counts as ``mu + 1 = 1`` (no crossing there).
_NO_CROSSING = 1.0


def _g(mu) -> float:
    return float(mu) + 1.0 if np.isfinite(mu) else _NO_CROSSING


def locate_period_doublings(system, hb: HarmonicBalance, solve: Callable, segments, *, tolerance: float = 1e-7,
                            max_steps: int = 40) -> list:
    """The -1 crossings between pairs of branch points, ``segments``: ``(pa, za, pb, zb)`` each
    (``nu = 1`` unknowns of `hb`).

    Illinois regula falsi on ``g = mu + 1`` (``mu`` the most negative real multiplier,
    :func:`exact_negative_multipliers`) in the parameter, to `tolerance` relative, all segments
    in step: each step converges one solution per unfinished segment with `solve(p, z0) -> z`
    (started from the straight line between the segment's points, so it stays on this branch
    even where the curve is multivalued; a linear system's multipliers do not depend on the
    solution, so there it is solved only at the crossing found) and asks their multipliers in
    one batched evaluation (the variational equations of a batch share their steps: on the NLTV
    pair, H = 32, one to eight members cost the same 17-19 ms). The ends' multipliers come in one
    batch first. On the NLTV pair's four crossings (H = 32, N = 1024) 0.36-0.48 s in a warm
    process, where Hill's crossings first, then the exact multipliers to confirm them, took
    0.52-0.57 s.

    **Returns:** one ``(PeriodDoublingPoint, None)`` or ``(None, reason)`` per segment (reason:
    the multipliers at the points do not change sign across -1, or what failed).
    """
    segments = [(float(pa), np.asarray(za, dtype=float), float(pb), np.asarray(zb, dtype=float))
                for pa, za, pb, zb in segments]
    solution_free = system.linearization() is system  # the multipliers do not depend on the solution
    out: list = [None] * len(segments)

    def solve_on(k, w):
        pa, za, pb, zb = segments[k]
        t = 0.0 if pb == pa else (w - pa) / (pb - pa)
        return solve(w, (1 - t) * za + t * zb)

    def failed(k, exc) -> None:
        out[k] = (None, f"locating the crossing failed: {type(exc).__name__}: {exc}")

    def multipliers(segment_of, zs, ws) -> list:
        """The multipliers at the points (one batch; point by point if the batch fails: a point
        that fails ends the search of its segment, ``segment_of[i]``, and is ``None``)."""
        try:
            return list(exact_negative_multipliers(system, hb, zs, ws))
        except Exception:  # noqa: BLE001 -- find the bad point(s), keep the others
            done = []
            for k, z, w in zip(segment_of, zs, ws):
                try:
                    done.append(exact_negative_multipliers(system, hb, [z], [w])[0])
                except Exception as exc:  # noqa: BLE001 -- reported, the nu = 1 curve is kept
                    failed(k, exc)
                    done.append(None)
            return done

    ends = multipliers([k for k in range(len(segments)) for _ in (0, 1)],
                       [s[1 + 2 * side] for s in segments for side in (0, 1)],
                       [s[2 * side] for s in segments for side in (0, 1)])
    brackets, best = {}, {}
    for k, (pa, za, pb, zb) in enumerate(segments):
        if out[k] is not None:  # an end's multiplier failed
            continue
        mu_a, mu_b = ends[2 * k], ends[2 * k + 1]
        ga, gb = _g(mu_a), _g(mu_b)
        if ga * gb > 0:
            out[k] = (None, f"the multipliers flagged a crossing between p = {pa:.9g} and {pb:.9g} that the "
                            f"exact/variational monodromy does not confirm (most negative real multipliers "
                            f"{mu_a:.6g}, {mu_b:.6g})")
            continue
        brackets[k] = IllinoisBracket(pa, ga, pb, gb)
        best[k] = (pa, za, mu_a, ga) if abs(ga) <= abs(gb) else (pb, zb, mu_b, gb)
    for _ in range(max_steps):
        active = [k for k in brackets if out[k] is None and best[k][3] != 0 and not brackets[k].within(tolerance)]
        if not active:
            break
        trial, zs = {}, {}
        for k in active:
            w = brackets[k].point()
            try:
                zs[k] = None if solution_free else solve_on(k, w)
                trial[k] = w
            except Exception as exc:  # noqa: BLE001 -- reported, the nu = 1 curve is kept
                failed(k, exc)
        keys = list(trial)
        values = multipliers(keys, [zs[k] for k in keys], [trial[k] for k in keys]) if keys else []
        for k, mu in zip(keys, values):
            if mu is None:
                continue
            gc = _g(mu)
            if abs(gc) <= abs(best[k][3]):
                best[k] = (trial[k], zs[k], mu, gc)
            brackets[k] = brackets[k].narrowed(trial[k], gc)
    for k in brackets:
        if out[k] is not None:
            continue
        w, z, mu, _ = best[k]
        pa, _, pb, _ = segments[k]
        try:
            z = solve_on(k, w) if z is None else z
        except Exception as exc:  # noqa: BLE001 -- reported, the nu = 1 curve is kept
            failed(k, exc)
            continue
        out[k] = (PeriodDoublingPoint(float(w), z, float(mu), (pa, pb)), None)
    return out


def locate_period_doubling(system, hb: HarmonicBalance, solve: Callable, pa: float, za, pb: float, zb, *,
                           tolerance: float = 1e-7, max_steps: int = 40):
    """The -1 crossing between branch points ``(pa, za)`` and ``(pb, zb)``:
    :func:`locate_period_doublings` of that one segment.

    **Returns:** ``(PeriodDoublingPoint, None)`` or ``(None, reason)`` when the exact multipliers
    do not confirm a crossing between the points.
    """
    return locate_period_doublings(system, hb, solve, [(pa, za, pb, zb)], tolerance=tolerance, max_steps=max_steps)[0]


# ============================================================================ following the nu = 2 branch


class DoubledBranch(NamedTuple):
    """A followed ``nu = 2`` branch, in path order from the bifurcation: parameter `p` (n,),
    unknowns `z` (n, size) of `hb` (the ``nu = 2`` discretisation), `residual` (n,), `amplitude`
    (n,) the half-order amplitude ``phi . (z - z_*)``, `status` (``"reached range end"``,
    ``"reconnected"``, ``"max amplitude"`` or ``"failed"``), `message`, `mode` ``phi``."""

    p: np.ndarray
    z: np.ndarray
    residual: np.ndarray
    amplitude: np.ndarray
    hb: HarmonicBalance
    status: str
    message: str
    mode: np.ndarray


def _end_leg(hb2, system, z, p, end, p_star, tolerance, max_points):
    """The arclength leg in the parameter from ``(p, z)`` that stops exactly at `end` (in the
    metric of :func:`~hbgear.engine.metric.continuation_functions`; ``z`` of the result in
    `hb2`'s unknowns)."""
    both, resid, fixed, sizes = continuation_functions(hb2, system, p_star)
    y = np.asarray(z, dtype=float) if sizes is None else np.asarray(z, dtype=float) / sizes
    leg = continuation(both, resid, y, float(p), end, sweep_method(p_star, end), max_points=max_points,
                       tolerance=tolerance, args=fixed)
    return leg if sizes is None else replace(leg, z=np.asarray(leg.z) * sizes)


def follow_period_doubled(system, point: PeriodDoublingPoint, harmonics: int, p_lo: float, p_hi: float, *,
                          harmonics2: int | None = None, samples2: int | None = None, tolerance: float = 1e-9,
                          max_points: int = 400, amplitude: float = 0.02, max_amplitude: float = 100.0,
                          progress=None) -> DoubledBranch:
    r"""Follow the ``nu = 2`` branch born at `point` while its parameter stays in ``[p_lo, p_hi]``.

    Continuation in the half-order amplitude ``a = phi . (z - z_*)`` with the parameter as an
    unknown, ``R_2(z, p) = 0``, ``phi . (z - z_*) = a``, from `amplitude` up to `max_amplitude`
    (in the system's scaled units). It ends: ``"reached range end"`` (the parameter left the range;
    the last leg is an arclength continuation in the parameter that stops exactly at that end),
    ``"reconnected"`` (the amplitude went back to zero: the branch rejoins the ``nu = 1`` curve at
    another period doubling), ``"max amplitude"`` (an unbounded branch?) or ``"failed"``.

    **Arguments:** `harmonics`: ``H`` of the ``nu = 1`` unknowns ``point.z``; `harmonics2`: of
    the ``nu = 2`` basis (default ``2 H``); `samples2`: its AFT samples (default
    ``max(256, 8 H2)``, even).
    """
    h2 = 2 * harmonics if harmonics2 is None else int(harmonics2)
    samples2 = samples2 or max(256, 8 * h2)
    hb2 = HarmonicBalance(system.ndof, h2, 2, samples2 + samples2 % 2)
    z_star = embed_subharmonic(point.z, system.ndof, harmonics, h2)
    p_star = float(point.p)
    phi, _ = half_order_mode(hb2, z_star, p_star, system)
    offset = float(phi @ z_star)
    sizes = arclength_sizes(hb2, system, p_star)  # the curve's metric: a soft mean does not fill the arclength
    scale = np.ones(hb2.size) if sizes is None else sizes
    both, resid = amplitude_residuals(hb2, system, p_star, phi, offset, sizes)
    method = PseudoArclength(ds=0.02, ds_min=1e-8, ds_max=0.25, max_angle_deg=5.0, parameter_scale=max_amplitude)
    leg = continuation(both, resid, np.append((z_star + amplitude * phi) / scale, 1.0), amplitude, max_amplitude,
                       method, max_points=max_points, tolerance=tolerance, progress=progress,
                       callback=lambda a, y: not p_lo <= float(y[-1]) * p_star <= p_hi)
    ps = np.asarray(leg.z)[:, -1] * p_star if len(leg) else np.zeros(0)
    zs = np.asarray(leg.z)[:, :-1] * scale if len(leg) else np.zeros((0, hb2.size))
    res = np.asarray(leg.residual)

    def result(ps, zs, res, status, message):
        return DoubledBranch(ps, zs, res, zs @ phi - offset if len(zs) else np.zeros(0), hb2, status, message, phi)

    if leg.status == Status.STOPPED and len(ps) >= 2:
        end = p_lo if ps[-1] < p_lo else p_hi
        k = len(ps) - 2  # the last point inside the range
        last = _end_leg(hb2, system, zs[k], ps[k], end, p_star, tolerance, max_points)
        ps = np.concatenate([ps[: k + 1], np.asarray(last.p)[1:]])
        zs = np.concatenate([zs[: k + 1], np.asarray(last.z)[1:]])
        res = np.concatenate([res[: k + 1], np.asarray(last.residual)[1:]])
        if last.success:
            return result(ps, zs, res, "reached range end", f"reached p = {end:.9g}")
        return result(ps, zs, res, "failed", f"last leg towards p = {end:.9g} stopped at p = {ps[-1]:.9g}: {last.message}")
    if leg.status == Status.TURNED_BACK:
        return result(ps, zs, res, "reconnected", f"the half-order amplitude went back to zero near p = {ps[-1]:.9g}: "
                      "the branch rejoins the nu = 1 curve there")
    if leg.status == Status.SUCCESS:
        return result(ps, zs, res, "max amplitude", f"half-order amplitude reached {max_amplitude:g} at p = {ps[-1]:.9g} "
                      "without leaving the range (unbounded branch?)")
    return result(ps, zs, res, "failed", f"{leg.status.name}: {leg.message}")
