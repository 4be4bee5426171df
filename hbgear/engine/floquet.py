r"""Floquet stability of periodic solutions: classification of multipliers and Hill's method.

A periodic solution ``q*(t)`` of ``M q'' = Q(s, q, q')`` is stable iff every Floquet multiplier
of the linearised equations ``M y'' = Q_q(t) y + Q_qd(t) y'`` has modulus below one (trivial
multipliers of a free coordinate excepted).

**Hill's method** (:func:`hill_multipliers`, :func:`hill_multipliers_batch`) on the
harmonic-balance Jacobian: of the quadratic eigenproblem ``(J + lam D1 + lam^2 D2) v = 0``,
whose ``2 n (2H+1)`` eigenvalues come in families of copies ``lam + i k w`` (one multiplier
each), the ``2n`` members whose eigenvectors are most concentrated on the central harmonics
are kept (Lazarus & Thomas 2010); multipliers ``exp(lam T)``, ``T = 2 pi / w``. By default
only those central eigenpairs are computed (refined from a low-harmonic sub-problem, batched
over points, see :mod:`hbgear.engine.hill`); ``method="dense"`` takes all eigenpairs of the
companion linearisation instead, with the same result.

Trivial multipliers: a system with a ``free_mean_dof`` (e.g. the gear pair's ``"reaction"``
boundary) has no restoring force on that coordinate, so its linearisation has the exponent 0
twice (a Jordan block: ``u = const``, ``u = t``); those (at most two, within
:data:`TRIVIAL_TOL` of 0) are dropped.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = [
    "TRIVIAL_TOL",
    "StabilityInfo",
    "classify",
    "hill_exponents",
    "hill_exponents_along",
    "hill_exponents_batch",
    "hill_follower",
    "hill_multipliers",
    "hill_multipliers_batch",
    "is_stable",
    "max_abs_multiplier",
    "most_negative_real",
    "neutral_mask",
    "period_doubling",
    "split_neutral",
    "stable_verdict",
    "stable_verdicts",
]

#: Multipliers within this distance of 1 (exponents within ``TRIVIAL_TOL/(2 pi)`` of 0, in
#: units of the base frequency) count as the trivial rigid-body ones of a free coordinate.
TRIVIAL_TOL = 1e-5


# ============================================================================ classification


class StabilityInfo(NamedTuple):
    """Summary of a set of Floquet multipliers.

    **Fields:** `max_abs` (largest modulus); `stable` (see :func:`is_stable`); `kind`: ``"stable"``,
    ``"period-doubling"`` (a real multiplier below -1: continue the ``nu = 2`` branch),
    ``"fold"`` (a real multiplier above +1) or ``"secondary-hopf"`` (a complex pair outside).
    """

    max_abs: float
    stable: bool
    kind: str


def max_abs_multiplier(multipliers) -> float:
    """``max |mu_i|`` (``nan`` for an empty or non-finite set)."""
    m = np.asarray(multipliers)
    if m.size == 0 or not np.all(np.isfinite(m)):
        return float("nan")
    return float(np.max(np.abs(m)))


def is_stable(multipliers, tol: float = 1e-9) -> bool:
    """``True`` iff every multiplier has ``|mu| <= 1 + tol`` (the trivial ones already dropped).

    The small tolerance keeps a neutrally stable mode (exactly on the unit circle up to
    rounding, e.g. an undamped model) from being reported unstable.
    """
    value = max_abs_multiplier(multipliers)
    return bool(np.isfinite(value) and value <= 1.0 + tol)


def neutral_mask(multipliers, neutral, tol: float) -> np.ndarray:
    """Which multipliers belong to modes a system knows to be neutral.

    For each value of `neutral` (e.g. ``exp(+-i w T)`` of an undamped mode the system adds by
    construction) the nearest multiplier not yet taken is marked if it lies within `tol` of it.
    Batched: `multipliers` ``(..., k)`` and `neutral` ``(..., t)`` with the same leading shape.

    **Returns:** a boolean mask of the shape of `multipliers`.
    """
    m = np.asarray(multipliers)
    targets = np.asarray(neutral)
    mask = np.zeros(m.shape, dtype=bool)
    if m.shape[-1] == 0:
        return mask
    for j in range(targets.shape[-1]):
        distance = np.where(mask, np.inf, np.abs(m - targets[..., j:j + 1]))
        nearest = np.argmin(distance, axis=-1)[..., None]
        hit = np.take_along_axis(distance, nearest, axis=-1) <= tol
        np.put_along_axis(mask, nearest, np.take_along_axis(mask, nearest, axis=-1) | hit, axis=-1)
    return mask


def split_neutral(multipliers, neutral, tol: float):
    """``(others, taken)`` of one set of multipliers: the multipliers less those of known neutral
    modes (:func:`neutral_mask`, order kept), and those; the verdict is :func:`is_stable` of ``others``."""
    m = np.asarray(multipliers)
    mask = neutral_mask(m, neutral, tol)
    return m[~mask], m[mask]


def stable_verdict(system, p, multipliers, nu: int = 1, tol: float = 1e-9) -> bool:
    """The stability of a solution of `system` at `p`: :func:`is_stable` of its multipliers (trivial
    ones already dropped) less the system's known neutral ones (:func:`split_neutral` with the
    system's ``neutral_multipliers(p, nu)``, within :data:`TRIVIAL_TOL`)."""
    return bool(stable_verdicts(system, np.asarray([p], dtype=float), np.asarray(multipliers)[None, :], nu, tol)[0])


def stable_verdicts(system, ps, multipliers, nu: int = 1, tol: float = 1e-9) -> np.ndarray:
    """:func:`stable_verdict` of many solutions at once: row ``i`` of `multipliers` ``(m, k)`` at
    ``ps[i]``. A row is stable iff all its multipliers are finite, at least one is not a known
    neutral one, and those have ``|mu| <= 1 + tol`` (:func:`is_stable` of what
    :func:`split_neutral` leaves: an empty set has no verdict, so it is not stable)."""
    m = np.asarray(multipliers)
    if m.shape[-1] == 0:
        return np.zeros(m.shape[:-1], dtype=bool)
    mask = neutral_mask(m, system.neutral_multipliers(np.asarray(ps, dtype=float), nu), TRIVIAL_TOL)
    finite = np.all(np.isfinite(m), axis=-1)
    with np.errstate(invalid="ignore"):
        largest = np.max(np.where(mask, 0.0, np.abs(m)), axis=-1)
    return finite & np.any(~mask, axis=-1) & (largest <= 1.0 + tol)


def period_doubling(multipliers, tol: float = 1e-9) -> bool:
    """``True`` iff a real multiplier lies below ``-1 - tol`` (it left through -1).

    The caller should then continue the sub-harmonic branch (``nu = 2``, MODEL.md section 6).
    "Real" means ``|Im mu| <= 1e-6 |mu|`` (a complex pair that collided on the negative real axis
    becomes real there).
    """
    return bool(most_negative_real(multipliers) < -1.0 - tol)


def most_negative_real(multipliers) -> float:
    """The most negative real multiplier (``nan`` if none); "real" as in :func:`period_doubling`."""
    m = np.asarray(multipliers)
    negative = m.real[(np.abs(m.imag) <= 1e-6 * np.maximum(np.abs(m), 1.0)) & (m.real < 0)]
    return float(np.min(negative)) if negative.size else float("nan")


def classify(multipliers, tol: float = 1e-9) -> StabilityInfo:
    """Stable, or how the dominant multiplier left the unit circle."""
    m = np.asarray(multipliers)
    value = max_abs_multiplier(m)
    if is_stable(m, tol):
        return StabilityInfo(value, True, "stable")
    if not np.isfinite(value):
        return StabilityInfo(value, False, "unknown")
    lead = m[np.argmax(np.abs(m))]
    if abs(lead.imag) <= 1e-6 * abs(lead):
        return StabilityInfo(value, False, "period-doubling" if lead.real < 0 else "fold")
    return StabilityInfo(value, False, "secondary-hopf")


# ============================================================================ Hill's method


def _zero_tol(system, drop_trivial: bool):
    """Exponent tolerance (``mu = lam / w``) of the trivial pair, or ``None`` when none is dropped."""
    if drop_trivial and getattr(system, "free_mean_dof", None) is not None:
        return TRIVIAL_TOL / (2.0 * np.pi)
    return None


def _exponents_and_multipliers(mu, w):
    """``(lam, mult)`` of exponents ``mu = lam / w``: by decreasing ``|mult|``, the two of a
    complex pair (equal moduli) with ``Im mult > 0`` first, so every route gives one order.
    `mu` may be a stack ``(m, k)`` with `w` ``(m,)``."""
    mult = np.exp(2.0 * np.pi * mu)
    order = np.lexsort((-mult.imag, -np.abs(mult)), axis=-1)
    return np.take_along_axis(mu, order, axis=-1) * np.asarray(w)[..., None], np.take_along_axis(mult, order, axis=-1)


def hill_exponents_batch(hb, zs, ps, system, *, drop_trivial: bool = True, copy_tol: float = 1e-6,
                         method: str = "auto", neighbours: bool = False):
    """:func:`hill_exponents` at many points ``(zs[i], ps[i])`` of one problem, as a list.

    The Hill matrices come from one jitted, vmapped call per chunk of points
    (:func:`hbgear.engine.hill.hill_pencils`); the refinement runs stacked over all points
    (:func:`hbgear.engine.hill.central_exponents`; with `neighbours`, for consecutive close
    points of a branch, most are seeded by a settled neighbour,
    :func:`hbgear.engine.hill.neighbour_seeded_central`: the same exponents, 1.45x faster on
    the NLTV pair's curve at H = 10). On the Duffing benchmark (H = 7) this is ~13x cheaper per
    point than one call per point.
    """
    from .hill import central_exponents, hill_quadratic

    ps = np.atleast_1d(np.asarray(ps, dtype=float))
    if ps.size == 0:
        return []
    a0, a1, a2, w = hill_quadratic(hb, zs, ps, system)
    mus = central_exponents(a0, a1, a2, hb.ndof, hb.harmonics, zero_tol=_zero_tol(system, drop_trivial),
                            copy_tol=copy_tol, method=method, neighbours=neighbours)
    if len({len(mu) for mu in mus}) == 1:  # one vectorised sort for the whole stack
        lam, mult = _exponents_and_multipliers(np.stack(mus), w)
        return list(zip(lam, mult))
    return [_exponents_and_multipliers(mu, wk) for mu, wk in zip(mus, w)]


def hill_follower(hb, system, *, drop_trivial: bool = True, copy_tol: float = 1e-6, predict: bool = True):
    """A :class:`hbgear.engine.hill.CentralFollower` for the branches of `system` discretised by
    `hb` (for :func:`hill_exponents_along`; `predict`: see there)."""
    from .hill import CentralFollower

    return CentralFollower(hb.ndof, hb.harmonics, zero_tol=_zero_tol(system, drop_trivial), copy_tol=copy_tol,
                           predict=predict)


def hill_exponents_along(hb, zs, ps, system, follower=None, **kwargs):
    """:func:`hill_exponents` at consecutive points ``(zs[i], ps[i])`` of a branch, each point's
    refinement seeded from the point before (:class:`hbgear.engine.hill.CentralFollower`: the
    same exponents as the unseeded way, which settles the points where the seeded way is not
    confident). `follower` (:func:`hill_follower`) carries the chain from one call to the next,
    so a branch can be passed in pieces; keywords as :func:`hill_follower` otherwise. Problems
    of at most :data:`~hbgear.engine.hill.FOLLOW_MIN_SIZE` unknowns go to
    :func:`hill_exponents_batch` (the point-by-point Python loop costs more there than the
    stacked seeds and refinements of all points at once), and so do systems with a free mean
    coordinate whose trivial exponents are dropped: their Jordan pair at 0 splits by rounding,
    and whether both halves lie within :data:`TRIVIAL_TOL` changes from point to point (the
    gear pair with the reaction boundary, H = 24: -4.8e-5 at 13259 rpm), which only the unseeded
    selection sees.
    """
    from .hill import FOLLOW_MIN_SIZE, hill_pencils

    ps = np.atleast_1d(np.asarray(ps, dtype=float))
    if ps.size == 0:
        return []
    follower = hill_follower(hb, system, **kwargs) if follower is None else follower
    if hb.size <= FOLLOW_MIN_SIZE or follower.zero_tol is not None:
        return hill_exponents_batch(hb, zs, ps, system, drop_trivial=follower.zero_tol is not None,
                                    copy_tol=follower.copy_tol, neighbours=True)
    zs = np.atleast_2d(np.asarray(zs, dtype=float))
    prepared = hb.prepare(system)
    out = []
    for lo in range(0, len(ps), 32):  # the pencils of 32 points at a time (13 MB at N = 130)
        parts, w = hill_pencils(hb, zs[lo:lo + 32], ps[lo:lo + 32], system, prepared)
        pencils = (abc for part in parts for abc in part)
        out += [_exponents_and_multipliers(follower(abc), wk) for abc, wk in zip(pencils, w)]
    return out


def hill_exponents(hb, z, p, system, *, drop_trivial: bool = True, copy_tol: float = 1e-6, method: str = "auto"):
    """The ``2n`` Floquet exponents picked from the Hill spectrum, and their multipliers.

    **Returns:** ``(lam, mult)``: exponents [1/s] and multipliers ``exp(lam T)`` over the base
    period ``T = 2 pi / w`` (``w = w_mesh / nu``), sorted by decreasing ``|mult|``.

    Of every family of copies ``lam + i k w`` of the quadratic eigenproblem
    ``(J + mu w D1 + mu^2 w^2 D2) v = 0`` (``lam = mu w``) the member whose eigenvector is most
    concentrated on the central harmonics is kept (:mod:`hbgear.engine.hill`). `method`: ``"dense"``
    (all eigenpairs of the companion linearisation) or ``"refined"`` = ``"auto"`` (the central
    eigenpairs only, by inverse iteration seeded from the low harmonics; the dense way where
    that is not confident): the same multipliers either way (to within 5e-12 relative in
    ``tests/test_hill.py``; 2e-14 to 6e-13 measured).
    With the reaction boundary the (at most two) exponents within ``TRIVIAL_TOL`` of 0 are
    dropped.
    """
    return hill_exponents_batch(hb, np.asarray(z)[None], [p], system, drop_trivial=drop_trivial,
                                copy_tol=copy_tol, method=method)[0]


def hill_multipliers(hb, z, p, system, **kwargs) -> np.ndarray:
    """Floquet multipliers of a harmonic-balance solution by Hill's method.

    **Arguments:** `hb`: the :class:`~hbgear.engine.hb.HarmonicBalance` used to solve; `z`: its scaled
    unknowns (``PeriodicSolution.z``); `p`: the parameter (pinion speed [rad/s] for a
    ``GearSystem`` in speed); `system`: the system. Keywords go to :func:`hill_exponents`.

    **Returns:** the ``2n`` multipliers (less the trivial pair of the reaction boundary) over
    the base period ``2 pi nu / w_mesh``, sorted by decreasing modulus.
    """
    return hill_exponents(hb, z, p, system, **kwargs)[1]


def hill_multipliers_batch(hb, zs, ps, system, **kwargs) -> list[np.ndarray]:
    """:func:`hill_multipliers` at many points of one problem (see :func:`hill_exponents_batch`)."""
    return [mult for _, mult in hill_exponents_batch(hb, zs, ps, system, **kwargs)]


