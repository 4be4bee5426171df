"""Floquet stability along a branch of periodic solutions, and unstable zones of linear systems.

At each point the multipliers come from the cheapest exact route that applies:

- **exact monodromy** (:func:`hbgear.engine.monodromy.multipliers_linear`, batched over the
  points) where the system's :meth:`~hbgear.engine.system.PeriodicSystem.linearization` holds
  along the solution (a linear system everywhere; e.g. the gear pair with backlash where the
  teeth keep contact);
- **the variational equations** elsewhere (:func:`hbgear.engine.monodromy.monodromy_variational`
  along the harmonic-balance orbits, :data:`VARIATIONAL_POINTS` neighbouring points integrated
  together in one compiled program): the multipliers of the model's equations linearised about
  each orbit, to the integrator's tolerance (:data:`VARIATIONAL_RTOL`). On the NLTV gear pair
  (arctan, H = 32, N = 1024, 756 points over 3000-20000 rpm) 0.35-0.55 s for the curve, within
  3.2e-8 of a run at rtol 1e-12, where Hill's method took 2.0-2.1 s and was 7.8e-4 off (its
  truncation and the sampling of the friction's steep Jacobian); the same stability verdicts.
- **Hill's method** within :data:`FOLD_WINDOW` points of the branch's folds (`folds`), for
  systems whose force jumps at instants the state decides (declared event functions,
  :mod:`hbgear.engine.events`), and everywhere on request (``method="hill"``), along each run of neighbouring points with every
  point seeded from the one before (:func:`hbgear.engine.floquet.hill_exponents_along`), while its
  matrices are at most :data:`HILL_MAX_SIZE` square (beyond, the variational equations: Hill's
  eigenproblems grow as ``(n (2H+1))^3`` and its selection of the central exponents among
  ``2H+1`` copies gets less reliable). At a fold of the computed curve a multiplier is +1
  because the harmonic-balance Jacobian is singular there, and Hill's exponents are those of
  that Jacobian's Hill matrix: the stability changes exactly at the fold. The variational
  equations along the truncated orbits put that crossing off the fold by the truncation error:
  on the relieved ISO pair at H = 12, N = 256 (partial contact loss), up to five points on the
  stable side of a fold came out unstable. Where the force jumps at a state-dependent instant
  (formulation A's friction load of a pair that loses contact), the harmonic-balance residual
  integrates the jump where it moves (its Jacobian holds the instant's sensitivity, a saltation
  in effect) and the variational equations would not: on ``examples/iso_tip_relief.toml`` at
  9400.94 rpm (an unstable branch between folds) the largest multiplier converges to 1.28890
  by Hill's method (H = 24, 48, 96: 1.288932, 1.288896, 1.288896) and to 1.51490 by the
  variational equations along the same orbits.

Multipliers are over the base period of the discretisation (``nu`` excitation periods). A batch
that fails is redone point by point, so one bad point costs only itself (``None``).
"""

from __future__ import annotations

import sys
from typing import NamedTuple

import numpy as np

from .floquet import hill_exponents_along, hill_follower, hill_multipliers, stable_verdicts

__all__ = ["BRANCH_METHODS", "BranchStability", "branch_stability", "unstable_zones", "leaves_through", "HILL_BATCH",
           "HILL_MAX_SIZE", "VARIATIONAL_POINTS", "ZONE_SCAN_SUBDIVISIONS", "uses_hill"]

#: Points per call of :func:`~hbgear.engine.floquet.hill_exponents_along` (the progress bar
#: steps by this; a batch that fails is redone point by point).
HILL_BATCH = 128

#: Largest Hill matrix (``hb.size = n (2H+1)``) for which a branch's multipliers come from Hill's
#: method; beyond it from the variational equations. On the NLTV pair at 200 rpm (n = 2, H = 512,
#: size 2050) Hill took 84 s a point and returned three multipliers at 0.97836 where the
#: variational monodromy (DOP853, rtol 1e-10) has two and two at 2.5e-12; a batch of six points
#: of the variational equations took 5.9 s. Every bundled example is below it (130-390).
HILL_MAX_SIZE = 512

#: Points on either side of a fold that take Hill's method (module docstring).
FOLD_WINDOW = 8

#: Relative and absolute tolerances of the branch's variational equations (per member of a batch).
#: The orbits they follow are truncated: on the NLTV curve above the multipliers along the H = 32
#: and H = 64 orbits differ by up to 6.5e-6 (3000 rpm) and by 1.1e-8 at 16000-19000 rpm, so the
#: integration need not be much finer than that. Against a run at rtol 1e-12 the curve's
#: multipliers are within 3.2e-8 at rtol 1e-8 (0.50-0.56 s), 6.9e-10 at 1e-9 (0.69-0.78 s),
#: 5.6e-7 at 1e-7 (0.34-0.38 s), with the same verdicts at every point.
VARIATIONAL_RTOL, VARIATIONAL_ATOL = 1e-8, 1e-10

#: Points per batched integration of the variational equations. The batch shares its steps
#: (each member's spikes of the friction's Jacobian sit at its own instants), so larger batches
#: take more steps but cost less per point up to ~64: the NLTV curve above in 0.92-1.13 s with
#: batches of 16, 0.89-0.96 s with 64 (rtol 1e-10); one member alone per integration (vmapped, its
#: own steps) took 2.8-4.4 s.
VARIATIONAL_POINTS = 64

#: Sub-intervals per branch step of the exact scan for unstable zones (:func:`unstable_zones`).
ZONE_SCAN_SUBDIVISIONS = 6


class BranchStability(NamedTuple):
    """Multipliers along a branch: `multipliers` (a list, an array per point or ``None`` where
    it failed), `max_abs` and `stable` (arrays, NaN where unknown), `method` (text) and `warning`
    (text or ``None``)."""

    multipliers: list
    max_abs: np.ndarray
    stable: np.ndarray
    method: str
    warning: str | None


def _progress(total, label, progress):
    if not total or progress is False or not (progress or sys.stderr.isatty()):
        return None
    try:
        from tqdm.auto import tqdm
    except ImportError:  # pragma: no cover
        return None
    return tqdm(total=total, desc=label, leave=False, file=sys.stderr)


def _runs(indices) -> list[list[int]]:
    """`indices` (increasing) cut into runs of consecutive values (neighbours on the branch)."""
    runs: list[list[int]] = []
    for i in indices:
        if runs and i == runs[-1][-1] + 1:
            runs[-1].append(i)
        else:
            runs.append([i])
    return runs


def _hill_in_batches(hb, system, ps, zs, indices, out, progress, label) -> list[str]:
    """Hill multipliers at the points `indices` into ``out[i]``, a batch at a time along each run
    of neighbouring points (each point seeded from the one before:
    :func:`~hbgear.engine.floquet.hill_exponents_along`); a failing batch is redone point by
    point. **Returns:** the failure messages."""
    failures = []
    bar = _progress(len(indices), label, progress)
    for run in _runs(indices):
        follower = hill_follower(hb, system)
        for lo in range(0, len(run), HILL_BATCH):
            batch = run[lo:lo + HILL_BATCH]
            _fill(batch, lambda rows: [m for _, m in hill_exponents_along(hb, zs[rows], ps[rows], system, follower)],
                  lambda i: hill_multipliers(hb, zs[i], float(ps[i]), system), out, ps, failures,
                  on_batch_failure=follower.reset)
            if bar is not None:
                bar.update(len(batch))
    if bar is not None:
        bar.close()
    return failures


def _fill(batch, many, one, out, ps, failures, on_batch_failure=None) -> None:
    """``out[i] = many(batch)[k]`` for the points ``i = batch[k]``; if that fails, ``out[i] = one(i)``
    point by point (after `on_batch_failure`), a failing point's message appended to `failures`."""
    try:
        for i, m in zip(batch, many(batch)):
            out[i] = np.asarray(m)
        return
    except Exception:  # noqa: BLE001 -- find the bad point(s), keep the others
        if on_batch_failure is not None:
            on_batch_failure()
    for i in batch:
        try:
            out[i] = np.asarray(one(i))
        except Exception as exc:  # noqa: BLE001 -- one bad point must not lose the curve
            failures.append(f"p = {ps[i]:.9g}: {type(exc).__name__}: {exc}")


def _jumps_with_the_state(system, p) -> bool:
    """Whether `system` declares event functions (:mod:`hbgear.engine.events`: its force jumps
    where the state says, e.g. a friction load that exists while two flanks touch)."""
    from .events import declared

    return bool(declared(system, float(p)))


def uses_hill(hb) -> bool:
    """Whether a branch discretised by `hb` takes Hill's method where no exact route applies
    (its matrices at most :data:`HILL_MAX_SIZE` square), else the variational equations."""
    return hb.size <= HILL_MAX_SIZE


def _variational_in_batches(hb, system, ps, zs, indices, out, progress, label) -> list[str]:
    """Multipliers over the base period from the variational equations along the solutions at the
    points `indices`, :data:`VARIATIONAL_POINTS` of them per integration, into ``out[i]``; a
    failing batch is redone point by point. **Returns:** the failure messages."""
    from .monodromy import drop_trivial, monodromy_variational, state_synthesis

    def multipliers(rows):
        coefficients = np.stack([hb.decode(system, zs[i])[0] for i in rows])
        base = np.array([float(hb.base_frequency(system, ps[i])) for i in rows])
        phi = monodromy_variational(system, ps[rows], state_synthesis(coefficients, hb.harmonics, base), hb.nu,
                                    rtol=VARIATIONAL_RTOL, atol=VARIATIONAL_ATOL)
        return drop_trivial(np.linalg.eigvals(phi), system)  # as Hill's and the exact route's

    failures = []
    bar = _progress(len(indices), label, progress)
    for lo in range(0, len(indices), VARIATIONAL_POINTS):
        batch = list(indices[lo:lo + VARIATIONAL_POINTS])
        _fill(batch, multipliers, lambda i: multipliers([i])[0], out, ps, failures)
        if bar is not None:
            bar.update(len(batch))
    if bar is not None:
        bar.close()
    return failures


def exact_batch_size(system) -> int:
    """Parameter values per batched exact-monodromy evaluation: 4096 at ``2n = 4`` states, fewer
    for more (``65536 / (2n)^2``, at least 256), so a batch's Magnus steps stay ~tens of MB. Each
    evaluation costs a few model evaluations in Python whatever its size (the LTV example's zone
    scan of 12 000 values: 0.24-0.31 s in batches of 512, 0.19-0.23 s in batches of 4096)."""
    return max(256, 65536 // (2 * int(system.ndof)) ** 2)


def _exact_in_batches(linear, ps, indices, out, nu) -> None:
    """Exact multipliers of the linear system at the points `indices` (per excitation period,
    raised to ``nu``: over the base period), :func:`exact_batch_size` points per evaluation."""
    from .monodromy import multipliers_linear

    idx = np.asarray(indices)
    batch = exact_batch_size(linear)
    for lo in range(0, len(idx), batch):
        part = idx[lo:lo + batch]
        for k, m in zip(part, np.asarray(multipliers_linear(linear, ps[part])) ** nu):
            out[k] = m


#: The ways :func:`branch_stability` takes where no exact route applies.
BRANCH_METHODS = ("variational", "hill")


def branch_stability(hb, system, ps, zs, *, method: str = "variational", folds=(), progress=None,
                     label="Floquet multipliers") -> BranchStability:
    """Floquet multipliers over the base period at every point ``(ps[i], zs[i])`` of a branch of
    `system` discretised by `hb` (module docstring: exact monodromy where it applies, else the
    variational equations, Hill's method within :data:`FOLD_WINDOW` points of the indices
    `folds`, or everywhere with ``method="hill"``).

    **Returns:** a :class:`BranchStability`; stability by :func:`~hbgear.engine.floquet.stable_verdict`
    (the system's known neutral modes left out).
    """
    if method not in BRANCH_METHODS:
        raise ValueError(f"branch_stability: method = {method!r}; allowed: {', '.join(map(repr, BRANCH_METHODS))}")
    ps, zs = np.asarray(ps, dtype=float), np.asarray(zs, dtype=float)
    n = len(ps)
    out: list = [None] * n
    linear = system.linearization()
    exact = [i for i in range(n) if linear is not None and (linear is system or system.in_linear_regime(hb, zs[i], ps[i]))]
    taken = set(exact)
    rest = [i for i in range(n) if i not in taken]
    fallback = None
    if exact:
        try:
            _exact_in_batches(linear, ps, exact, out, hb.nu)
        except Exception as exc:  # noqa: BLE001 -- the general route instead
            fallback = f"exact monodromy failed ({type(exc).__name__}: {exc}); the general route used"
            rest, exact = sorted(rest + exact), []
    hill_text = "Hill's method (hbgear.engine.floquet.hill_exponents_along)"
    variational_text = "the variational equations (hbgear.engine.monodromy.monodromy_variational)"
    if not uses_hill(hb):
        hill, rest = [], rest
        if method == "hill":
            variational_text = variational_text[:-1] + f"; Hill's matrices would be {hb.size} > {HILL_MAX_SIZE} square)"
    elif method == "hill" or (rest and _jumps_with_the_state(system, ps[rest[0]])):
        hill, rest = rest, []
        if method != "hill":
            hill_text = hill_text[:-1] + ("; the force jumps at instants the state decides, which the variational "
                                          "equations would need saltation matrices for)")
    else:
        near = {i for f in folds for i in range(int(f) - FOLD_WINDOW, int(f) + FOLD_WINDOW + 1)}
        hill, rest = [i for i in rest if i in near], [i for i in rest if i not in near]
    failures = _hill_in_batches(hb, system, ps, zs, hill, out, progress, label) if hill else []
    failures += _variational_in_batches(hb, system, ps, zs, rest, out, progress, label) if rest else []
    parts = [text for text, ok in ((variational_text, rest), (hill_text + (" near the folds" if rest else ""), hill)) if ok]
    rest_text = " and ".join(parts)
    rest = rest + hill
    exact_text = "exact monodromy (hbgear.engine.monodromy.multipliers_linear)"
    if not rest:
        method_text = exact_text
    elif not exact:
        method_text = rest_text
    else:
        method_text = (f"{exact_text} at the {len(exact)} points in the linear regime (e.g. the teeth keep contact), "
                  f"{rest_text} at the {len(rest)} others")
    warning = fallback
    if failures:
        warning = ((fallback + "; ") if fallback else "") + (
            f"Floquet multipliers failed at {len(failures)} point(s), NaN there; first: {failures[0]}")
    max_abs = np.array([np.nan if m is None else (float(np.max(np.abs(m))) if m.size else 0.0) for m in out])
    stable = np.full(n, np.nan)
    for size in {m.size for m in out if m is not None}:  # one vectorised verdict per multiplier count
        rows = [i for i, m in enumerate(out) if m is not None and m.size == size]
        stable[rows] = stable_verdicts(system, ps[rows], np.stack([out[i] for i in rows]), hb.nu)
    return BranchStability(out, max_abs, stable, method_text, warning)


def leaves_through(multiplier) -> str:
    """``"-1"`` (period doubling), ``"+1"`` (divergence) or ``"complex"`` (a complex pair)."""
    if abs(multiplier.imag) > 1e-6 * abs(multiplier):
        return "complex"
    return "-1" if multiplier.real < 0 else "+1"


def unstable_zones(system, ps, subdivisions: int = ZONE_SCAN_SUBDIVISIONS) -> list[dict]:
    """Parameter intervals where a linear system's steady state is unstable, by exact monodromy
    on a grid `subdivisions` times finer than the points `ps` (a zone narrower than a branch step
    can lie between two stable points of the branch; this scan finds it to the grid's resolution).

    **Returns:** one dict per zone: ``parameter_from``, ``parameter_to`` (first and last unstable
    grid values), ``max_abs_floquet`` and ``multiplier`` at its maximum (per excitation period),
    ``leaves_through`` (:func:`leaves_through`), ``resolution`` (the grid step there) and
    ``between_points`` (no point of `ps` falls inside).
    """
    from .monodromy import multipliers_linear

    p = np.sort(np.asarray(ps, dtype=float))
    frac = np.arange(subdivisions) / subdivisions
    grid = np.concatenate([(p[:-1, None] + np.diff(p)[:, None] * frac).ravel(), p[-1:]])
    batch = exact_batch_size(system)
    mult = np.concatenate([np.asarray(multipliers_linear(system, grid[lo:lo + batch]))
                           for lo in range(0, len(grid), batch)])
    unstable = ~stable_verdicts(system, grid, mult)
    zones = []
    edges = np.flatnonzero(np.diff(np.concatenate([[0], unstable.astype(int), [0]])))
    for start, stop in zip(edges[::2], edges[1::2]):
        peak = start + int(np.argmax(np.abs(mult[start:stop]).max(axis=1)))
        lead = mult[peak][np.argmax(np.abs(mult[peak]))]
        lo, hi = grid[start], grid[stop - 1]
        step = float(np.max(np.diff(grid[max(start - 1, 0):min(stop + 1, len(grid))]), initial=0.0))
        zones.append({
            "parameter_from": float(lo),
            "parameter_to": float(hi),
            "max_abs_floquet": float(abs(lead)),
            "multiplier": [float(lead.real), float(lead.imag)],
            "leaves_through": leaves_through(lead),
            "resolution": step,
            "between_points": not bool(np.any((p >= lo) & (p <= hi))),
        })
    return zones
