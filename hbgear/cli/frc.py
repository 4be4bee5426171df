"""`hbgear frc CONFIG`: frequency-response curve by pseudo-arclength continuation in speed.

The pinion speed runs over ``[sweep] speed_rpm_start -> speed_rpm_stop`` (either may be the
larger) with the model and ``[solver]`` settings of the config; folds are followed and located.
Writes into the output directory (INTERFACE.md), all through :mod:`hbgear.outputs.io`:

- `frc.csv`: ``speed_rpm, mesh_freq_hz, dte_mean_um, dte_rms_um, dte_p2p_um, dynamic_factor,
  max_abs_floquet, stable, nu, residual`` -- one row per continuation point in path order (a fold
  shows as the speed going back; located folds are rows of their own); then the rows of every
  period-doubled branch (``nu = 2``), each in path order from its bifurcation;
- `frc.json`: run summary -- status and message, ``H`` (and how it was chosen), ``nu``, number of
  points, folds (speeds), stability availability, ``period_doubling`` (one record per -1
  crossing: bracket, located speed and multiplier, the ``nu = 2`` branch's status, message,
  point count, first frc.csv row, ranges) and ``period_doubling_rule``, ``stability.unstable_zones``
  (linear models: :func:`unstable_zones`, exact monodromy on a finer grid), continuation settings,
  timings, the config;
- `floquet.csv`: ``row, speed_rpm, index, multiplier_re, multiplier_im, multiplier_abs`` -- every
  Floquet multiplier (over the base period) of every ``nu = 1`` point, ``row`` indexing the data
  rows of `frc.csv` (not written with ``--no-stability``);
- `frc.png`: DTE RMS and peak-to-peak against speed, unstable points and folds marked, the
  ``nu = 2`` branches in green, the period doublings as squares.

``harmonics = "auto"``: :func:`hbgear.gear.solve.auto_harmonics` at both ends of the sweep, the larger
``H`` is used for the whole curve. Stability: exact monodromy for linear models (batched), and
for backlash models (otherwise linear) at the points where the teeth never separate (the
linearisation is exactly the linear model's there); Hill's method per point otherwise, classified
by :func:`hbgear.engine.floquet.is_stable`; if that module is missing, the Floquet columns are NaN and
`frc.json` says so. If the continuation stops before the stop speed, the curve computed so
far is still written (with the status in `frc.json`) and the run ends with exit status 1.

Period doubling (MODEL.md section 6): on a ``nu = 1`` curve, every pair of consecutive points
between which a real multiplier crosses -1 (:func:`hbgear.engine.floquet.period_doubling` changes) is
refined on that segment (exact / variational monodromy, :func:`_locate_on_segment`; a crossing
the exact multipliers do not confirm is listed as ``"not confirmed"``), and the ``nu = 2`` branch
born there is followed (:func:`follow_period_doubling`, ``H2 = 2 H``, twice the AFT samples)
until it leaves the sweep range (the last point exactly at its end), rejoins the ``nu = 1`` curve,
or fails. Its points get the same stability method over two mesh periods. A failure is a record
in frc.json and a warning on stderr; the ``nu = 1`` curve is kept and the exit status stays 0.
``--no-period-doubling`` turns it off; by default it is on where cheap
(:data:`PD_AUTO_MAX_UNKNOWNS`), ``--period-doubling`` forces it.
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import asdict

import jax.numpy as jnp
import numpy as np

from ..build import build_model
from . import Command, register
from ..engine.continuation import PseudoArclength, Status, continuation, illinois, sweep_method
from ..engine.hb import residual_functions
from ..errors import ConvergenceError
from ..engine.hb import HarmonicBalance
from ..outputs.io import save_figure_atomic, write_csv_atomic, write_json_atomic
from ..gear.solve import (PeriodicSolution, auto_harmonics, rad_s_to_rpm, read_outs, rpm_to_rad_s, solve_periodic,
                     start_guess)
from ..gear.system import GearSystem, linear_equivalent

__all__ = ["FRC", "COLUMNS", "FLOQUET_COLUMNS", "floquet_rows", "run", "plot_frc",
           "PD_AUTO_MAX_UNKNOWNS", "period_doubling_enabled", "follow_period_doubling"]

COLUMNS = (
    "speed_rpm",
    "mesh_freq_hz",
    "dte_mean_um",
    "dte_rms_um",
    "dte_p2p_um",
    "dynamic_factor",
    "max_abs_floquet",
    "stable",
    "nu",
    "residual",
)

#: Columns of `floquet.csv`: one row per multiplier of every ``nu = 1`` point, ``row`` being the
#: point's data row in `frc.csv` (0 = first), multipliers over the base period, sorted by
#: decreasing modulus.
FLOQUET_COLUMNS = ("row", "speed_rpm", "index", "multiplier_re", "multiplier_im", "multiplier_abs")


def floquet_rows(speed_rpm, multipliers) -> list[list]:
    """The `floquet.csv` rows of the points whose multipliers are known (``None`` skipped)."""
    rows = []
    for row, (rpm, mult) in enumerate(zip(speed_rpm, multipliers)):
        if mult is None:
            continue
        mult = np.asarray(mult, dtype=complex)
        for k, m in enumerate(mult[np.argsort(-np.abs(mult), kind="stable")]):
            rows.append([row, float(rpm), k, float(m.real), float(m.imag), float(abs(m))])
    return rows


def add_arguments(parser) -> None:
    parser.add_argument("--no-progress", action="store_true", help="no progress bar (default: only on a terminal)")
    parser.add_argument("--no-stability", action="store_true", help="skip the Floquet multipliers (columns NaN)")
    pd = parser.add_mutually_exclusive_group()
    pd.add_argument("--no-period-doubling", dest="period_doubling", action="store_const", const=False, default=None,
                    help="do not look for period doublings nor follow the nu = 2 branches")
    pd.add_argument("--period-doubling", dest="period_doubling", action="store_const", const=True,
                    help="follow the nu = 2 branches even where the default cost rule would skip them")


def _harmonics(config, model, omega_start, omega_stop, nu):
    """``(H, samples, start solution or None, description)``: with ``H`` from the config no
    solution is computed here (the continuation corrects :func:`~hbgear.gear.solve.start_guess`)."""
    so = config.solver
    if so.harmonics is not None:
        samples = so.time_samples + so.time_samples % nu
        return so.harmonics, samples, None, f"from the config ({so.harmonics})"
    kw = dict(nu=nu, tolerance=so.tolerance, max_iterations=so.max_iterations)
    at_start, at_stop = auto_harmonics(model, omega_start, **kw), auto_harmonics(model, omega_stop, **kw)
    harmonics = max(at_start.harmonics, at_stop.harmonics)
    samples = max(so.time_samples, 4 * harmonics * nu)
    samples += samples % nu
    start = solve_periodic(model, omega_start, harmonics=harmonics, nu=nu, samples=samples,
                           tolerance=so.tolerance, max_iterations=so.max_iterations)
    text = (f"auto: hbgear.gear.solve.auto_harmonics gave H = {at_start.harmonics} at the start speed and "
            f"{at_stop.harmonics} at the stop speed; the larger is used")
    return harmonics, samples, start, text


def _linear_equivalent(model):
    """:func:`hbgear.gear.system.linear_equivalent` of `model` (the candidate, no solution)."""
    return linear_equivalent(model)


def _keeps_contact(model, hb, z, p) -> bool:
    """True if the solution `z` (of `hb`, speed `p`) has the linear equivalent
    (:func:`hbgear.gear.system.linear_equivalent`: contact kept, compressive loads)."""
    return linear_equivalent(model, PeriodicSolution.from_z(model, float(p), z, hb)) is not None


#: Points per call of :func:`hbgear.engine.floquet.hill_multipliers_batch` (one vmapped Hill-matrix
#: evaluation and one stacked eigen-decomposition for small problems; the progress bar steps
#: by this much).
HILL_BATCH = 32


def _hill_in_batches(hb, system, p, z, indices, out, progress, label):
    """Hill multipliers at the points `indices` into ``out[i]``, a batch at a time.

    A batch that fails is redone point by point, so one bad point costs only itself (NaN).
    **Returns:** the failure messages.
    """
    from ..engine.floquet import hill_multipliers, hill_multipliers_batch

    p, z = np.asarray(p, dtype=float), np.asarray(z, dtype=float)
    failures = []
    batches = [indices[k : k + HILL_BATCH] for k in range(0, len(indices), HILL_BATCH)]
    bar = None
    if indices and progress is not False and (progress or sys.stderr.isatty()):
        try:
            from tqdm.auto import tqdm

            bar = tqdm(total=len(indices), desc=label, leave=False, file=sys.stderr)
        except ImportError:  # pragma: no cover
            pass
    for batch in batches:
        try:
            for i, m in zip(batch, hill_multipliers_batch(hb, z[batch], p[batch], system)):
                out[i] = np.asarray(m)
        except Exception:  # noqa: BLE001 -- find the bad point(s), keep the others
            for i in batch:
                try:
                    out[i] = np.asarray(hill_multipliers(hb, jnp.asarray(z[i]), float(p[i]), system))
                except Exception as exc:  # noqa: BLE001 -- one bad point must not lose the curve
                    failures.append(f"{rad_s_to_rpm(p[i]):.6g} rpm: {type(exc).__name__}: {exc}")
        if bar is not None:
            bar.update(len(batch))
    if bar is not None:
        bar.close()
    return failures


def _multipliers(hb, system, p, z, progress=None, label="Floquet multipliers"):
    """Floquet multipliers over the base period (``hb.nu`` mesh periods) at every point ``(p[i], z[i])``.

    Exact monodromy (:func:`hbgear.gear.monodromy.multipliers_linear` per mesh period, batched, raised
    to ``nu``) for linear models and, for models whose only non-linearity is the backlash, at the
    points that keep contact (:func:`_linear_equivalent`); Hill's method
    (:func:`hbgear.engine.floquet.hill_multipliers_batch`, in batches) at the others.

    **Returns:** ``(multipliers, method, warning)``: a list of arrays (``None`` where it failed),
    the method text and a warning (or ``None``).
    **Raises:** `ImportError` if :mod:`hbgear.engine.floquet` is unavailable.
    """
    from ..gear.monodromy import multipliers_linear

    model = system.model
    n = len(p)
    out = [None] * n
    linear = _linear_equivalent(model)
    exact_idx, hill_idx = [], []
    for i in range(n):
        if linear is not None and (linear is model or _keeps_contact(model, hb, z[i], p[i])):
            exact_idx.append(i)
        else:
            hill_idx.append(i)
    fallback = None
    if exact_idx:
        try:
            idx = np.asarray(exact_idx)
            for lo in range(0, len(idx), 256):
                part = idx[lo : lo + 256]
                mult = np.asarray(multipliers_linear(linear, np.asarray(p, dtype=float)[part])) ** hb.nu
                for k, m in zip(part, mult):
                    out[k] = m
        except Exception as exc:  # noqa: BLE001 -- fall back to Hill
            fallback = f"exact monodromy failed ({type(exc).__name__}: {exc}); Hill's method used"
            hill_idx = sorted(hill_idx + exact_idx)
            exact_idx = []
    failures = _hill_in_batches(hb, system, p, z, hill_idx, out, progress, label)
    exact_text = "exact monodromy (hbgear.gear.monodromy.multipliers_linear)"
    hill_text = "Hill's method (hbgear.engine.floquet.hill_multipliers_batch)"
    if not hill_idx:
        method = exact_text
    elif not exact_idx:
        method = hill_text
    else:
        method = (f"{exact_text} at the {len(exact_idx)} points that keep contact (the backlash model is "
                  f"linear there), {hill_text} at the {len(hill_idx)} others")
    warning = fallback
    if failures:
        warning = ((fallback + "; ") if fallback else "") + (
            f"Floquet multipliers failed at {len(failures)} point(s), NaN there; first: {failures[0]}")
    return out, method, warning


#: Sub-intervals per curve step of the exact-monodromy scan for unstable zones (linear models).
ZONE_SCAN_SUBDIVISIONS = 6


def _leaves_through(multiplier) -> str:
    """``"-1"`` (period doubling), ``"+1"`` (divergence) or ``"complex"`` (a complex pair)."""
    if abs(multiplier.imag) > 1e-6 * abs(multiplier):
        return "complex"
    return "-1" if multiplier.real < 0 else "+1"


def unstable_zones(model, speeds_rad_s, subdivisions: int = ZONE_SCAN_SUBDIVISIONS) -> list[dict]:
    """Speed intervals where a linear model's steady state is unstable, by exact monodromy on a grid
    `subdivisions` times finer than the curve's points (:func:`hbgear.gear.monodromy.multipliers_linear`).

    A zone narrower than a curve step can lie between two stable points of the curve; this scan
    finds it to the grid's resolution. Each zone: ``speed_rpm_from``, ``speed_rpm_to`` (first and
    last unstable grid speed), ``max_abs_floquet`` and the multiplier at its maximum, where it
    leaves the unit circle (``"-1"``: period doubling, ``"+1"``: divergence, ``"complex"``),
    ``resolution_rpm`` (the grid step at the zone) and
    ``between_curve_points`` (no point of the curve itself falls inside).
    """
    from ..engine.floquet import is_stable
    from ..gear.monodromy import multipliers_linear

    p = np.sort(np.asarray(speeds_rad_s, dtype=float))
    frac = np.arange(subdivisions) / subdivisions
    grid = np.concatenate([(p[:-1, None] + np.diff(p)[:, None] * frac).ravel(), p[-1:]])
    mult = np.concatenate([np.asarray(multipliers_linear(model, grid[lo:lo + 512]))
                           for lo in range(0, len(grid), 512)])
    unstable = np.array([not is_stable(m) for m in mult])
    zones = []
    edges = np.flatnonzero(np.diff(np.concatenate([[0], unstable.astype(int), [0]])))
    for start, stop in zip(edges[::2], edges[1::2]):
        peak = start + int(np.argmax(np.abs(mult[start:stop]).max(axis=1)))
        lead = mult[peak][np.argmax(np.abs(mult[peak]))]
        lo, hi = grid[start], grid[stop - 1]
        inside = np.any((p >= lo) & (p <= hi))
        step = float(np.max(np.diff(grid[max(start - 1, 0):min(stop + 1, len(grid))]), initial=0.0))
        zones.append({
            "speed_rpm_from": float(rad_s_to_rpm(lo)),
            "speed_rpm_to": float(rad_s_to_rpm(hi)),
            "max_abs_floquet": float(abs(lead)),
            "multiplier": [float(lead.real), float(lead.imag)],
            "leaves_through": _leaves_through(lead),
            "resolution_rpm": float(rad_s_to_rpm(step)),
            "between_curve_points": not bool(inside),
        })
    return zones


def _floquet(hb, system, branch, progress):
    """``(max |multiplier| per point over the base period, stable per point, method, warning, multipliers)``.

    See :func:`_multipliers`; NaN (and ``None`` multipliers) where unavailable.
    """
    values = np.full(len(branch), np.nan)
    stable = np.full(len(branch), np.nan)
    try:
        from ..engine.floquet import is_stable
        multipliers, method, warning = _multipliers(hb, system, np.asarray(branch.p), np.asarray(branch.z), progress)
    except ImportError as exc:  # not there yet: NaN columns and a warning
        return values, stable, None, f"Floquet multipliers not computed: hbgear.engine.floquet unavailable ({exc})", \
            [None] * len(branch)
    for i, m in enumerate(multipliers):
        if m is not None:
            values[i] = float(np.max(np.abs(m))) if m.size else 0.0
            stable[i] = float(is_stable(m))
    return values, stable, method, warning, multipliers


# ============================================================================ period doubling

#: Default rule (``--period-doubling`` / ``--no-period-doubling`` override it): the -1 crossings
#: of a ``nu = 1`` curve are always located and listed in frc.json; their ``nu = 2`` branches are
#: followed when the model is non-linear and the ``nu = 2`` problem has at most this many unknowns,
#: ``ndof (4 H + 1)`` (its basis has ``H2 = 2 H`` harmonics of ``w_m / 2``). Each ``nu = 2`` point
#: costs a Jacobian of that size per Newton step and, where the teeth separate, a Hill eigenproblem
#: of twice that size: measured on 2 cores ~0.02 s at 65 unknowns, ~0.2 s at 194, ~0.9 s at 386,
#: so at the limit a branch of ~100 points costs about as much as the ``nu = 1`` curve's stability.
#: (A linear model has no bounded ``nu = 2`` branch: its crossings are located, never followed.)
PD_AUTO_MAX_UNKNOWNS = 200


def period_doubling_enabled(config, args, model, harmonics, nu) -> tuple[bool, bool, str]:
    """``(locate the crossings?, follow the nu = 2 branches?, why)``.

    From ``--no-period-doubling`` / ``--period-doubling``, else the config key
    ``sweep.period_doubling`` (``true`` / ``false`` / ``"auto"``, when the config has it), else the
    rule: follow where the teeth can separate (backlash bounds the branch) and the ``nu = 2``
    problem has at most :data:`PD_AUTO_MAX_UNKNOWNS` unknowns. Only ``nu = 1`` curves are searched.
    """
    if nu != 1:
        return False, False, f"period doublings are only looked for on nu = 1 curves (this one has nu = {nu})"
    flag, source = getattr(args, "period_doubling", None), "--period-doubling / --no-period-doubling"
    if flag is None:
        flag, source = getattr(config.sweep, "period_doubling", None), "sweep.period_doubling"
        if isinstance(flag, str):
            flag = None if flag.strip().lower() == "auto" else flag.strip().lower() in ("true", "on", "yes", "1")
    if flag is False:
        return False, False, f"off ({source})"
    if model.is_linear:
        return True, False, ("crossings located; a linear model has no bounded nu = 2 branch to follow "
                             "(the response grows without bound inside the instability tongue)")
    if flag:
        return True, True, f"on ({source})"
    if model.mesh_is_linear:
        return True, False, ("auto: crossings located, nu = 2 branches not followed: without backlash the mesh "
                             "stays linear and only the friction limits the branch, which grows like a linear "
                             "model's (NLTV pair, H = 16: DTE 12 -> 528 um peak-to-peak within 3 rpm, not ended "
                             "in 4000 points); --period-doubling to force")
    unknowns = model.ndof * (4 * harmonics + 1)
    if unknowns <= PD_AUTO_MAX_UNKNOWNS:
        return True, True, f"auto: on (nu = 2 problem of {unknowns} <= {PD_AUTO_MAX_UNKNOWNS} unknowns)"
    return True, False, (f"auto: crossings located, nu = 2 branches not followed (nu = 2 problem of {unknowns} > "
                         f"{PD_AUTO_MAX_UNKNOWNS} unknowns; --period-doubling to force)")


def _pd_flags(multipliers) -> np.ndarray:
    """Per point: 1.0 if a real multiplier lies below -1 (:func:`hbgear.engine.floquet.period_doubling`), 0.0 if
    not, NaN if unknown."""
    from ..engine.floquet import period_doubling

    return np.array([np.nan if m is None else float(period_doubling(m)) for m in multipliers])


def _pd_multiplier(model, hb, sol) -> float:
    """Most negative real multiplier per mesh period of the ``nu = 1`` solution `sol`: exact
    monodromy where :func:`_linear_equivalent` applies, the variational equations otherwise."""
    from ..gear.bifurcation import period_doubling_multiplier

    linear = _linear_equivalent(model)
    if linear is not None and (linear is model or _keeps_contact(model, hb, sol.z, sol.omega_pinion)):
        return period_doubling_multiplier(linear, sol)
    return period_doubling_multiplier(model, sol)


def _locate_on_segment(model, hb, branch, i, harmonics, samples, tolerance, max_iterations,
                       speed_tolerance=1e-7, max_steps=40):
    """The -1 crossing between continuation points ``i`` and ``i+1`` (Illinois regula falsi on
    ``mu + 1`` in speed, each ``nu = 1`` solve started from the straight line between the two points,
    so it stays on this branch even where the curve is multivalued).

    Where the multiplier needs the variational equations (~0.15 s an evaluation) the crossing of
    Hill's multipliers (~10 ms an evaluation) is located first; the exact multiplier there and
    Hill's slope over the segment give the next point, stepped out until the exact multipliers
    change sign (:func:`_exact_bracket`); they then locate the crossing to `speed_tolerance`.
    Hill's crossing is off the exact one by its truncation and sampling error (2e-6 relative at
    H = 32, N = 1024 on the NLTV pair; 4e-5 at N = 256). Without that bracket the whole segment
    is searched with the exact multipliers.

    **Returns:** :class:`hbgear.gear.bifurcation.PeriodDoublingPoint`, or ``None`` with the reason if the
    exact multipliers do not confirm the crossing.
    """
    from ..gear.bifurcation import PeriodDoublingPoint

    pa, pb = float(branch.p[i]), float(branch.p[i + 1])
    za, zb = np.asarray(branch.z[i]), np.asarray(branch.z[i + 1])

    def solve(w):
        t = 0.0 if pb == pa else (w - pa) / (pb - pa)
        return solve_periodic(model, w, harmonics=harmonics, nu=1, samples=samples, tolerance=tolerance,
                              max_iterations=max_iterations, z0=(1 - t) * za + t * zb)

    def g(w):
        sol = solve(w)
        mu = _pd_multiplier(model, hb, sol)
        return (mu + 1.0 if np.isfinite(mu) else 1.0), (sol, mu)

    bracket = None
    if _linear_equivalent(model) is None:
        hill = _hill_crossing(model, hb, solve, pa, pb, speed_tolerance * 10, max_steps)
        if hill is not None:
            try:
                bracket = _exact_bracket(g, *hill, pa, pb)
            except Exception:  # noqa: BLE001 -- a solve that fails near Hill's crossing: the whole segment
                bracket = None
    if bracket is None:
        bracket = (pa, *g(pa), pb, *g(pb))
    lo, ga, da, hi, gb, db = bracket
    if ga * gb > 0:
        return None, (f"the multipliers flagged a crossing between {rad_s_to_rpm(pa):.6g} and {rad_s_to_rpm(pb):.6g} rpm "
                      f"that the exact/variational monodromy does not confirm (most negative real multipliers "
                      f"{da[1]:.6g}, {db[1]:.6g})")
    (w, (sol, mu), _), _ = illinois(g, lo, ga, hi, gb, (lo, da, ga) if abs(ga) < abs(gb) else (hi, db, gb),
                                    speed_tolerance, max_steps)
    return PeriodDoublingPoint(float(w), rad_s_to_rpm(float(w)), sol, float(mu),
                               (rad_s_to_rpm(pa), rad_s_to_rpm(pb))), None


#: Smallest first step (relative) from Hill's crossing towards the exact one (:func:`_exact_bracket`).
HILL_MIN_STEP = 1e-6


def _exact_bracket(g, w0, slope, pa, pb):
    """``(a, g(a)..., b, g(b)...)`` with a sign change of the exact ``g``, from Hill's crossing
    `w0`: the next point is the exact crossing predicted with Hill's `slope`, overshot by half
    (at least ``HILL_MIN_STEP`` away), then steps four times longer until the sign changes;
    ``None`` at the end of the segment ``[pa, pb]`` without one."""
    low, high = min(pa, pb), max(pa, pb)
    g0, d0 = g(w0)
    if g0 == 0:
        return w0, g0, d0, w0, g0, d0
    step = -1.5 * g0 / slope if slope != 0 and np.isfinite(slope) else 0.0
    step = math.copysign(max(abs(step), HILL_MIN_STEP * abs(w0)), step)
    while True:
        w1 = min(max(w0 + step, low), high)
        g1, d1 = g(w1)
        if g0 * g1 <= 0:
            return w0, g0, d0, w1, g1, d1
        if w1 in (low, high):
            return None
        step *= 4.0


def _hill_crossing(model, hb, solve, pa, pb, tolerance, max_steps):
    """``(w, slope)``: the -1 crossing of Hill's most negative real multiplier between `pa` and
    `pb` (to `tolerance` relative) and the slope of its ``mu + 1`` over the segment, or ``None``
    when Hill's multipliers do not bracket a crossing there (or fail)."""
    from ..engine.floquet import hill_multipliers, most_negative_real

    system = GearSystem(model)

    def g(w):
        mu = most_negative_real(hill_multipliers(hb, solve(w).z, w, system))
        return (mu + 1.0 if np.isfinite(mu) else 1.0), None

    try:
        (ga, _), (gb, _) = g(pa), g(pb)
        if ga * gb > 0:
            return None
        (w, _, _), _ = illinois(g, pa, ga, pb, gb, (pa, None, ga), tolerance, max_steps)
    except Exception:  # noqa: BLE001 -- Hill only starts the search; the exact multipliers decide
        return None
    return w, (gb - ga) / (pb - pa)


def follow_period_doubling(model, point, omega_lo, omega_hi, *, harmonics2, samples2, tolerance=1e-9,
                           max_points=400, amplitude=0.02, max_amplitude=100.0, progress=None):
    r"""Follow the ``nu = 2`` branch born at `point` while it stays in ``[omega_lo, omega_hi]``.

    As :func:`hbgear.gear.bifurcation.continue_period_doubled`: continuation in the half-order amplitude
    ``a = phi . (z - z_*)`` with the speed as an unknown (regular at the bifurcation whether the
    branch is vertical, super- or subcritical), from `amplitude` up to `max_amplitude` static
    deflections. It ends

    - ``"reached sweep end"``: the speed left the range; the last leg is an arclength continuation
      in speed that stops exactly at that end of the range;
    - ``"reconnected"``: the amplitude went back to zero (the branch rejoins the ``nu = 1`` curve,
      at another period doubling);
    - ``"max amplitude"``: the half-order amplitude reached `max_amplitude` (an unbounded branch);
    - ``"failed"``: the continuation could not go on (or `max_points`), message from it.

    **Returns:** ``(omega (n,), z (n, size), residual (n,), hb2, status, message)``.
    """
    from ..gear.bifurcation import amplitude_residuals, embed_subharmonic, half_order_mode

    sol = point.solution
    hb2 = HarmonicBalance(model.ndof, harmonics2, 2, samples2)
    system = GearSystem(model)
    z_star = embed_subharmonic(sol.z, model.ndof, sol.harmonics, harmonics2)
    w_star = float(point.omega)
    phi, _ = half_order_mode(hb2, z_star, w_star, system)
    offset = float(phi @ z_star)

    both, resid = amplitude_residuals(hb2, system, w_star, phi, offset)

    def outside(w):
        return w < omega_lo or w > omega_hi

    method = PseudoArclength(ds=0.02, ds_min=1e-8, ds_max=0.25, max_angle_deg=5.0, parameter_scale=max_amplitude)
    y0 = np.append(z_star + amplitude * phi, 1.0)
    leg = continuation(both, resid, y0, amplitude, max_amplitude, method, max_points=max_points,
                       tolerance=tolerance, callback=lambda a, y: outside(float(y[-1]) * w_star), progress=progress)
    omega = np.asarray(leg.z)[:, -1] * w_star if len(leg) else np.zeros(0)
    zs = np.asarray(leg.z)[:, :-1] if len(leg) else np.zeros((0, hb2.size))
    res = np.asarray(leg.residual)
    if leg.status == Status.STOPPED and len(omega) >= 2:
        end = omega_lo if omega[-1] < omega_lo else omega_hi
        k = len(omega) - 2  # the last point inside the range
        both_p, resid_p, fixed = residual_functions(hb2, system)
        last = continuation(both_p, resid_p, zs[k], float(omega[k]), end, sweep_method(w_star, end),
                            max_points=max_points, tolerance=tolerance, args=fixed)
        omega = np.concatenate([omega[: k + 1], np.asarray(last.p)[1:]])
        zs = np.concatenate([zs[: k + 1], np.asarray(last.z)[1:]])
        res = np.concatenate([res[: k + 1], np.asarray(last.residual)[1:]])
        if last.success:
            return omega, zs, res, hb2, "reached sweep end", f"reached {rad_s_to_rpm(end):.6g} rpm"
        return omega, zs, res, hb2, "failed", (f"last leg in speed towards {rad_s_to_rpm(end):.6g} rpm stopped at "
                                               f"{rad_s_to_rpm(omega[-1]):.6g} rpm: {last.message}")
    if leg.status == Status.TURNED_BACK:
        return omega, zs, res, hb2, "reconnected", (
            f"the half-order amplitude went back to zero near {rad_s_to_rpm(omega[-1]):.6g} rpm: the branch rejoins "
            "the nu = 1 curve there")
    if leg.status == Status.SUCCESS:
        return omega, zs, res, hb2, "max amplitude", (
            f"half-order amplitude reached {max_amplitude:g} static deflections at {rad_s_to_rpm(omega[-1]):.6g} rpm "
            "without leaving the sweep range (unbounded branch?)")
    return omega, zs, res, hb2, "failed", f"{leg.status.name}: {leg.message}"


def _period_doubling(model, hb, system, branch, multipliers, *, harmonics, samples, config, follow, sweep_rpm,
                     progress):
    """Locate the -1 crossings along the ``nu = 1`` curve and follow their ``nu = 2`` branches.

    **Returns:** ``(records for frc.json, rows for frc.csv, plot data per branch)``.
    """
    from ..engine.floquet import is_stable

    so, sw = config.solver, config.sweep
    flags = _pd_flags(multipliers)
    candidates = [i for i in range(len(flags) - 1)
                  if np.isfinite(flags[i]) and np.isfinite(flags[i + 1]) and flags[i] != flags[i + 1]]
    omega_lo, omega_hi = (rpm_to_rad_s(min(sweep_rpm)), rpm_to_rad_s(max(sweep_rpm)))
    records, rows, curves = [], [], []
    ends = []  # speeds where followed branches rejoined the nu = 1 curve
    h2, samples2 = 2 * harmonics, 2 * samples
    for i in candidates:
        t0 = time.perf_counter()
        rec = {"bracket_rpm": [float(rad_s_to_rpm(branch.p[i])), float(rad_s_to_rpm(branch.p[i + 1]))],
               "bracket_rows": [i, i + 1],
               "unstable_side": "below" if (flags[i] > flags[i + 1]) == (branch.p[i] < branch.p[i + 1]) else "above"}
        try:
            point, why = _locate_on_segment(model, hb, branch, i, harmonics, samples, so.tolerance, so.max_iterations)
        except Exception as exc:  # noqa: BLE001 -- reported, the nu = 1 curve is kept
            point, why = None, f"locating the crossing failed: {type(exc).__name__}: {exc}"
        if point is None:
            rec.update(status="not confirmed" if why.startswith("the multipliers") else "failed", message=why,
                       points=0, time_s=time.perf_counter() - t0)
            records.append(rec)
            continue
        rec.update(speed_rpm=float(point.speed_rpm), mesh_freq_hz=float(point.omega * model.teeth_pinion / (2 * math.pi)),
                   multiplier=float(point.multiplier))
        joined = [e for e in ends if abs(e - point.omega) <= 5e-3 * point.omega]
        if model.is_linear:
            rec.update(status="not followed", points=0,
                       message="linear model: the nu = 2 branch is vertical and unbounded at the crossing "
                       "(a parametric instability), nothing to follow")
        elif not follow:
            rec.update(status="not followed", points=0, message="nu = 2 branches not followed here (see "
                       "period_doubling_rule; --period-doubling forces it)")
        elif joined:
            rec.update(status="joined", points=0, message="the nu = 2 branch of an earlier crossing rejoins the "
                       "nu = 1 curve here; not followed twice")
        else:
            try:
                omega, zs, res, hb2, status, message = follow_period_doubling(
                    model, point, omega_lo, omega_hi, harmonics2=h2, samples2=samples2, tolerance=so.tolerance,
                    max_points=sw.max_points, progress=progress)
            except Exception as exc:  # noqa: BLE001 -- reported, the nu = 1 curve is kept
                omega, zs, res, hb2 = np.zeros(0), None, None, None
                status, message = "failed", f"branch switching failed: {type(exc).__name__}: {exc}"
            if status == "reconnected" and len(omega):
                ends.append(float(omega[-1]))
            t_follow = time.perf_counter()
            block = []
            if len(omega):
                system2 = GearSystem(model)
                try:
                    mults, method2, warning2 = _multipliers(hb2, system2, omega, zs, progress,
                                                            label="Floquet multipliers (nu = 2)")
                except ImportError:
                    mults, method2, warning2 = [None] * len(omega), None, "hbgear.engine.floquet unavailable"
                read = read_outs(model, omega, zs, hb2)
                for i, (w, r, m) in enumerate(zip(omega, res, mults)):
                    floq = np.nan if m is None else (float(np.max(np.abs(m))) if m.size else 0.0)
                    st = np.nan if m is None else int(is_stable(m))
                    block.append([float(rad_s_to_rpm(w)), float(w) * model.teeth_pinion / (2 * math.pi),
                                  *(float(read[key][i]) for key in ("dte_mean_um", "dte_rms_um", "dte_p2p_um",
                                                                    "dynamic_factor")),
                                  floq, st, 2, float(r)])
                rec.update(stability_method=method2, stability_warning=warning2)
            arr = np.array([b[:8] for b in block], dtype=float).reshape(len(block), 8)
            rec.update(
                status=status, message=message, points=len(block), harmonics=h2, time_samples=samples2,
                first_row=len(branch) + len(rows),
                speed_rpm_range=[float(arr[:, 0].min()), float(arr[:, 0].max())] if len(block) else None,
                dte_p2p_um_range=[float(arr[:, 4].min()), float(arr[:, 4].max())] if len(block) else None,
                unstable_points=int(np.sum(arr[:, 7] == 0)) if len(block) else 0,
                stability_time_s=time.perf_counter() - t_follow,
            )
            rows.extend(block)
            if block:
                curves.append(arr)
        rec["time_s"] = time.perf_counter() - t0
        records.append(rec)
    return records, rows, curves


def plot_frc(speed_rpm, rms_um, p2p_um, stable, fold_rows, title, subharmonic=(), pd_points=(), zones=()):
    """Figure: DTE RMS and peak-to-peak against speed; unstable points (red) and folds marked.

    `subharmonic`: ``nu = 2`` branches, arrays of frc.csv rows (columns as :data:`COLUMNS`, first 8),
    drawn in another colour; `pd_points`: ``(speed_rpm, rms_um, p2p_um)`` of located period doublings;
    `zones`: :func:`unstable_zones` records, shaded.
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=(8, 6.5))
    axes = fig.subplots(2, 1, sharex=True)
    unstable = stable == 0
    for ax, col, values, label in ((axes[0], 3, rms_um, "DTE RMS [um]"), (axes[1], 4, p2p_um, "DTE peak-to-peak [um]")):
        ax.plot(speed_rpm, values, color="k", lw=1.0, label="HB continuation (nu = 1)")
        for k, zone in enumerate(zones):
            ax.axvspan(zone["speed_rpm_from"], zone["speed_rpm_to"], color="tab:red", alpha=0.15, lw=0,
                       label="unstable zone (exact scan)" if k == 0 else None)
        if np.any(unstable):
            ax.plot(speed_rpm[unstable], values[unstable], "o", ms=3, color="tab:red", label="unstable")
        if len(fold_rows):
            ax.plot(speed_rpm[fold_rows], values[fold_rows], "D", ms=6, mfc="none", color="tab:blue", label="fold")
        for k, rows in enumerate(subharmonic):
            ax.plot(rows[:, 0], rows[:, col], color="tab:green", lw=1.2,
                    label="period-doubled branch (nu = 2)" if k == 0 else None)
            bad = rows[:, 7] == 0
            if np.any(bad):
                ax.plot(rows[bad, 0], rows[bad, col], "x", ms=4, color="tab:red",
                        label="unstable (nu = 2)" if k == 0 else None)
        if len(pd_points):
            pts = np.asarray(pd_points, dtype=float).reshape(-1, 3)
            ax.plot(pts[:, 0], pts[:, col - 2], "s", ms=6, mfc="none", color="tab:purple", label="period doubling")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8, loc="upper left")
    axes[1].set_xlabel("pinion speed [rpm]")
    axes[0].set_title(title, fontsize=10)
    fig.tight_layout()
    return fig


def run(config, args, out_dir) -> int:
    clock = time.perf_counter
    t0 = clock()
    progress = False if getattr(args, "no_progress", False) else None
    model = build_model(config)
    so, sw = config.solver, config.sweep
    nu = so.subharmonic
    omega_start, omega_stop = rpm_to_rad_s(sw.speed_rpm_start), rpm_to_rad_s(sw.speed_rpm_stop)
    harmonics, samples, start, harmonics_rule = _harmonics(config, model, omega_start, omega_stop, nu)
    hb = HarmonicBalance(model.ndof, harmonics, nu, samples)
    system = GearSystem(model)
    residual_and_jacobians, residual, fixed = residual_functions(hb, system)
    step = None if sw.step_rpm is None else rpm_to_rad_s(sw.step_rpm)
    method = sweep_method(omega_start, omega_stop, step)

    def solve_start():
        return solve_periodic(model, omega_start, harmonics=harmonics, nu=nu, samples=samples,
                              tolerance=so.tolerance, max_iterations=so.max_iterations)

    def follow(z0, **kw):
        return continuation(residual_and_jacobians, residual, z0, omega_start, omega_stop, method,
                            max_points=sw.max_points, tolerance=so.tolerance, progress=progress, args=fixed, **kw)

    guess = start_guess(model, hb, system) if start is None else None
    if start is None and guess is None:
        start = solve_start()
    t_start = clock()
    if guess is not None:  # Newton from the guess inside the continuation's compiled corrector
        branch = follow(guess, start_iterations=so.max_iterations)
        if branch.status == Status.START_FAILED:  # the staged start of solve_periodic (or its error)
            start = solve_start()
            t_start = clock()
    if start is not None:
        branch = follow(start.z)
    t_cont = clock()
    t_compile = t_start + branch.start_seconds

    if getattr(args, "no_stability", False):
        floquet, stable = np.full(len(branch), np.nan), np.full(len(branch), np.nan)
        stability_method, stability_warning = None, "Floquet multipliers skipped (--no-stability)"
        multipliers = [None] * len(branch)
    else:
        floquet, stable, stability_method, stability_warning, multipliers = _floquet(hb, system, branch, progress)

    zones, zones_rule = [], "not scanned: the model is not linear (zones are the unstable curve points)"
    if getattr(args, "no_stability", False):
        zones_rule = "not scanned (--no-stability)"
    elif model.is_linear and len(branch) > 1:
        zones = unstable_zones(model, branch.p)
        zones_rule = (f"exact monodromy on a grid {ZONE_SCAN_SUBDIVISIONS}x finer than the curve's points "
                      "(linear model); zones narrower than the grid step can still be missed")
    t_stab = clock()

    look, follow, pd_rule = period_doubling_enabled(config, args, model, harmonics, nu)
    pd_records, pd_rows, pd_curves = [], [], []
    if look and all(m is None for m in multipliers):
        pd_rule = "period doublings not looked for: no Floquet multipliers (--no-stability or unavailable)"
    elif look:
        pd_records, pd_rows, pd_curves = _period_doubling(
            model, hb, system, branch, multipliers, harmonics=harmonics, samples=samples, config=config,
            follow=follow, sweep_rpm=(sw.speed_rpm_start, sw.speed_rpm_stop), progress=progress)
    t_pd = clock()

    speed_rpm = rad_s_to_rpm(np.asarray(branch.p))
    speed_rpm[0] = sw.speed_rpm_start  # exact ends (no rpm -> rad/s -> rpm rounding)
    if branch.success:
        speed_rpm[-1] = sw.speed_rpm_stop
    read = read_outs(model, branch.p, branch.z, hb)  # the summary of every point, batched
    table = np.column_stack([
        speed_rpm,
        np.asarray(branch.p) * model.teeth_pinion / (2 * math.pi),
        read["dte_mean_um"],
        read["dte_rms_um"],
        read["dte_p2p_um"],
        read["dynamic_factor"],
        floquet,
        stable,
        np.full(len(branch), nu),
        branch.residual,
    ]).reshape(len(branch), len(COLUMNS))
    rows = [[*row[:8], int(nu), row[9]] for row in table]
    for row in rows:
        if not math.isnan(row[7]):
            row[7] = int(row[7])
    for row in pd_rows:
        if not math.isnan(row[7]):
            row[7] = int(row[7])
    write_csv_atomic(out_dir / "frc.csv", COLUMNS, rows + pd_rows)
    if any(m is not None for m in multipliers):
        write_csv_atomic(out_dir / "floquet.csv", FLOQUET_COLUMNS, floquet_rows(speed_rpm, multipliers))

    folds = branch.folds
    fold_info = [
        {"index": int(i), "speed_rpm": float(speed_rpm[i]), "mesh_freq_hz": float(table[i, 1]),
         "dte_rms_um": float(table[i, 3]), "dte_p2p_um": float(table[i, 4]),
         "kind": "maximum speed" if branch.tangent_p[i - 1] > 0 else "minimum speed"}
        for i in folds
    ]
    title = (f"{model.coupling} {model.formulation}, {model.boundary}, H={harmonics}, nu={nu}: "
             f"{len(branch)} points, {len(folds)} folds" + ("" if branch.success else f" [{branch.status.name}]")
             + (f", {len(pd_curves)} nu=2 branch(es)" if pd_curves else ""))
    pd_points = []
    for rec in pd_records:
        if "speed_rpm" in rec:
            j = rec["bracket_rows"][0]
            sol = PeriodicSolution.from_z(model, rpm_to_rad_s(rec["speed_rpm"]), branch.z[j], hb).summary()
            pd_points.append((rec["speed_rpm"], sol["dte_rms_um"], sol["dte_p2p_um"]))
    fig = plot_frc(speed_rpm, table[:, 3], table[:, 4], stable, folds, title, pd_curves, pd_points, zones)
    save_figure_atomic(fig, out_dir / "frc.png", dpi=120)
    t_out = clock()

    n_steps = max(len(branch) - 1, 1)
    peak = int(np.argmax(table[:, 4])) if len(branch) else 0
    summary = {
        "command": "frc",
        "status": branch.status.name.lower(),
        "success": branch.success,
        "message": branch.message,
        "speed_rpm_start": sw.speed_rpm_start,
        "speed_rpm_stop": sw.speed_rpm_stop,
        "speed_rpm_reached": float(speed_rpm[-1]),
        "harmonics": harmonics,
        "harmonics_rule": harmonics_rule,
        "nu": nu,
        "time_samples": samples,
        "points": len(branch),
        "rejected_steps": branch.rejected,
        "max_residual": float(np.max(branch.residual)),
        "tolerance": so.tolerance,
        "folds": fold_info,
        "fold_speeds_rpm": [f["speed_rpm"] for f in fold_info],
        "peak": {"speed_rpm": float(speed_rpm[peak]), "dte_p2p_um": float(table[peak, 4]),
                 "dte_rms_um": float(table[peak, 3])},
        "stability": {
            "available": bool(np.all(np.isfinite(floquet))),
            "method": stability_method,
            "warning": stability_warning,
            "criterion": "hbgear.engine.floquet.is_stable: all |multipliers| <= 1 + 1e-9 (trivial ones removed); "
            "max_abs_floquet is over the base period (nu mesh periods)",
            "unstable_points": int(np.sum(stable == 0)),
            "unstable_zones": zones,
            "unstable_zones_rule": zones_rule,
        },
        "period_doubling_rule": pd_rule,
        "period_doubling": pd_records,
        "continuation": asdict(method) | {"method": "pseudo-arclength", "parameter": "pinion speed [rad/s]"},
        "model": {"coupling": model.coupling, "formulation": model.formulation, "boundary": model.boundary,
                  "contact": model.contact, "friction_law": repr(model.friction), "ndof": model.ndof},
        "timings_s": {
            "start_solution": t_start - t0,
            "compile_and_start_point": t_compile - t_start,
            "continuation": t_cont - t_compile,
            "per_point_ms": 1e3 * (t_cont - t_compile) / n_steps,
            "stability": t_stab - t_cont,
            "period_doubling": t_pd - t_stab,
            "outputs": t_out - t_pd,
            "total": clock() - t0,
        },
        "config": config.to_dict(),
    }
    write_json_atomic(out_dir / "frc.json", summary)
    if not branch.success:
        raise ConvergenceError(
            f"frc continuation from {sw.speed_rpm_start:g} to {sw.speed_rpm_stop:g} rpm (H={harmonics}, nu={nu}) "
            f"stopped at {speed_rpm[-1]:.6g} rpm: {branch.message}. The partial curve ({len(branch)} points) was "
            f"written to {out_dir / 'frc.csv'} with the status in frc.json"
        )
    for r in pd_records:
        if r["status"] == "failed":
            print(f"frc: warning: period doubling near {r.get('speed_rpm', r['bracket_rpm'][0]):.6g} rpm: "
                  f"{r['message']} (nu = 1 curve and frc.json written)", file=sys.stderr)
    peak = summary["peak"]
    located = [r for r in pd_records if "speed_rpm" in r]
    followed = [r for r in located if r["points"] > 0]
    pd_text = ""
    zones = summary["stability"]["unstable_zones"]
    zones_text = ""
    if zones:
        hidden = sum(z["between_curve_points"] for z in zones)
        zones_text = (f"{len(zones)} unstable zone(s) by the fine exact scan"
                      + (f", {hidden} between curve points" if hidden else "") + "; ")
    if located:
        speeds = ", ".join(f"{r['speed_rpm']:.6g}" for r in located)
        points = sum(r["points"] for r in followed)
        pd_text = f"period doubling at {speeds} rpm ({len(followed)} nu = 2 branches followed, {points} points); "
    print(
        f"frc: {len(branch)} points from {sw.speed_rpm_start:g} to {sw.speed_rpm_stop:g} rpm (H={harmonics}, nu={nu}); "
        f"peak DTE p2p {peak['dte_p2p_um']:.4g} um at {peak['speed_rpm']:.6g} rpm; "
        f"{len(summary['fold_speeds_rpm'])} folds; {summary['stability']['unstable_points']} unstable points; "
        f"{zones_text}{pd_text}{summary['timings_s']['total']:.1f} s -> {out_dir}"
    )
    return 0


FRC = register(
    Command(
        name="frc",
        help="frequency-response curve by arc-length continuation over [sweep] (frc.csv/.json/.png)",
        add_arguments=add_arguments,
        run=run,
    )
)
