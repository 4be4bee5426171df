"""`hbgear frc CONFIG`: frequency-response curve by pseudo-arclength continuation in speed.

The pinion speed runs over ``[sweep] speed_rpm_start -> speed_rpm_stop`` (either may be the
larger) with the model and ``[solver]`` settings of the config; folds are followed and located.
Writes into the output directory (INTERFACE.md), all through :mod:`hbgear.io`:

- `frc.csv`: ``speed_rpm, mesh_freq_hz, dte_mean_um, dte_rms_um, dte_p2p_um, dynamic_factor,
  max_abs_floquet, stable, nu, residual`` -- one row per continuation point in path order (a fold
  shows as the speed going back; located folds are rows of their own);
- `frc.json`: run summary -- status and message, ``H`` (and how it was chosen), ``nu``, number of
  points, folds (speeds), stability availability, continuation settings, timings, the config;
- `frc.png`: DTE RMS and peak-to-peak against speed, unstable points and folds marked.

``harmonics = "auto"``: :func:`hbgear.solve.auto_harmonics` at both ends of the sweep, the larger
``H`` is used for the whole curve. Stability: exact monodromy for linear models (batched), Hill's
method per point otherwise, classified by :func:`hbgear.stability.is_stable`; if that module is
missing, the Floquet columns are NaN and `frc.json` says so. If the continuation stops before the stop speed, the curve computed so
far is still written (with the status in `frc.json`) and the run ends with exit status 1.
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import asdict

import jax.numpy as jnp
import numpy as np

from ..build import build_model
from ..cli import Command, register
from ..continuation import PseudoArclength, continuation
from ..errors import ConvergenceError
from ..hb import HarmonicBalance
from ..io import save_figure_atomic, write_csv_atomic, write_json_atomic
from ..solve import PeriodicSolution, auto_harmonics, rad_s_to_rpm, rpm_to_rad_s, solve_periodic
from ..system import GearSystem

__all__ = ["FRC", "COLUMNS", "run", "frc_method", "gear_residual_functions", "plot_frc"]

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


def add_arguments(parser) -> None:
    parser.add_argument("--no-progress", action="store_true", help="no progress bar (default: only on a terminal)")
    parser.add_argument("--no-stability", action="store_true", help="skip the Floquet multipliers (columns NaN)")


def gear_residual_functions(hb: HarmonicBalance, system):
    """``(residual_and_jacobians, residual)`` in the form :func:`~hbgear.continuation.continuation` takes."""

    def residual_and_jacobians(z, p):
        return hb.residual_and_jacobians(jnp.asarray(z), p, system)

    def residual(z, p):
        return hb.residual(jnp.asarray(z), p, system)

    return residual_and_jacobians, residual


def frc_method(omega_start, omega_stop, step_rad_s=None) -> PseudoArclength:
    """Continuation options for a speed sweep.

    ``p_ref`` = the larger end speed; the unknowns are in static deflections, so a step moves
    the DTE harmonics by at most 0.25 static deflection (``ds_max``) and the speed by at most
    1/100 of the range (``max_parameter_step``; at least ~100 points on a flat curve); tangents
    turn by at most 5 deg per step. First step: `step_rad_s` (``[sweep] step_rpm``) or 1/4 of
    the largest speed step.
    """
    scale = max(abs(omega_start), abs(omega_stop))
    dp_max = abs(omega_stop - omega_start) / scale / 100
    ds = dp_max / 4 if step_rad_s is None else step_rad_s / scale
    dp_max = max(dp_max, ds)
    return PseudoArclength(
        ds=ds, ds_min=min(1e-7, ds / 10), ds_max=max(0.25, ds), max_angle_deg=5.0,
        parameter_scale=scale, max_parameter_step=dp_max,
    )


def _harmonics(config, model, omega_start, omega_stop, nu):
    """``(H, samples, start solution, description)``."""
    so = config.solver
    if so.harmonics is not None:
        samples = so.time_samples + so.time_samples % nu
        start = solve_periodic(model, omega_start, harmonics=so.harmonics, nu=nu, samples=samples,
                               tolerance=so.tolerance, max_iterations=so.max_iterations)
        return so.harmonics, samples, start, f"from the config ({so.harmonics})"
    kw = dict(nu=nu, tolerance=so.tolerance, max_iterations=so.max_iterations)
    at_start, at_stop = auto_harmonics(model, omega_start, **kw), auto_harmonics(model, omega_stop, **kw)
    harmonics = max(at_start.harmonics, at_stop.harmonics)
    samples = max(so.time_samples, 4 * harmonics * nu)
    samples += samples % nu
    start = solve_periodic(model, omega_start, harmonics=harmonics, nu=nu, samples=samples,
                           tolerance=so.tolerance, max_iterations=so.max_iterations)
    text = (f"auto: hbgear.solve.auto_harmonics gave H = {at_start.harmonics} at the start speed and "
            f"{at_stop.harmonics} at the stop speed; the larger is used")
    return harmonics, samples, start, text


def _floquet(hb, system, branch, progress):
    """``(max |multiplier| per point over the base period, stable per point, method, warning)``.

    Linear models: exact monodromy (:func:`hbgear.stability.multipliers_linear`, per mesh period,
    raised to ``nu``), batched; otherwise Hill's method per point. NaN where unavailable.
    """
    values = np.full(len(branch), np.nan)
    stable = np.full(len(branch), np.nan)
    try:
        from ..stability import hill_multipliers, is_stable, multipliers_linear
    except ImportError as exc:  # not there yet: NaN columns and a warning
        return values, stable, None, f"Floquet multipliers not computed: hbgear.stability unavailable ({exc})"
    model = system.model
    if model.is_linear:
        try:
            for lo in range(0, len(branch), 256):
                mult = np.asarray(multipliers_linear(model, np.asarray(branch.p[lo : lo + 256]))) ** hb.nu
                for k, m in enumerate(mult):
                    values[lo + k] = float(np.max(np.abs(m))) if m.size else 0.0
                    stable[lo + k] = float(is_stable(m))
            return values, stable, "exact monodromy (hbgear.stability.multipliers_linear)", None
        except Exception as exc:  # noqa: BLE001 -- fall back to Hill
            fallback = f"exact monodromy failed ({type(exc).__name__}: {exc}); Hill's method used"
    else:
        fallback = None
    failures = []
    indices = range(len(branch))
    if progress is not False and (progress or sys.stderr.isatty()):
        try:
            from tqdm.auto import tqdm

            indices = tqdm(indices, desc="Floquet multipliers", leave=False, file=sys.stderr)
        except ImportError:  # pragma: no cover
            pass
    for i in indices:
        try:
            multipliers = np.asarray(hill_multipliers(hb, jnp.asarray(branch.z[i]), float(branch.p[i]), system))
            values[i] = float(np.max(np.abs(multipliers))) if multipliers.size else 0.0
            stable[i] = float(is_stable(multipliers))
        except Exception as exc:  # noqa: BLE001 -- one bad point must not lose the curve
            failures.append(f"{rad_s_to_rpm(branch.p[i]):.6g} rpm: {type(exc).__name__}: {exc}")
    warning = fallback
    if failures:
        warning = ((fallback + "; ") if fallback else "") + (
            f"Floquet multipliers failed at {len(failures)} point(s), NaN there; first: {failures[0]}")
    return values, stable, "Hill's method (hbgear.stability.hill_multipliers)", warning


def plot_frc(speed_rpm, rms_um, p2p_um, stable, fold_rows, title):
    """Figure: DTE RMS and peak-to-peak against speed; unstable points (red) and folds marked."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(8, 6.5))
    axes = fig.subplots(2, 1, sharex=True)
    unstable = stable == 0
    for ax, values, label in ((axes[0], rms_um, "DTE RMS [um]"), (axes[1], p2p_um, "DTE peak-to-peak [um]")):
        ax.plot(speed_rpm, values, color="k", lw=1.0, label="HB continuation")
        if np.any(unstable):
            ax.plot(speed_rpm[unstable], values[unstable], "o", ms=3, color="tab:red", label="unstable")
        if len(fold_rows):
            ax.plot(speed_rpm[fold_rows], values[fold_rows], "D", ms=6, mfc="none", color="tab:blue", label="fold")
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
    t_start = clock()

    hb = HarmonicBalance(model.ndof, harmonics, nu, samples)
    system = GearSystem(model)

    residual_and_jacobians, residual = gear_residual_functions(hb, system)
    residual_and_jacobians(start.z, omega_start)[0].block_until_ready()  # compile outside the timing
    residual(start.z, omega_start).block_until_ready()
    t_compile = clock()

    step = None if sw.step_rpm is None else rpm_to_rad_s(sw.step_rpm)
    method = frc_method(omega_start, omega_stop, step)
    branch = continuation(
        residual_and_jacobians, residual, start.z, omega_start, omega_stop, method,
        max_points=sw.max_points, tolerance=so.tolerance, progress=progress,
    )
    t_cont = clock()

    if getattr(args, "no_stability", False):
        floquet, stable = np.full(len(branch), np.nan), np.full(len(branch), np.nan)
        stability_method, stability_warning = None, "Floquet multipliers skipped (--no-stability)"
    else:
        floquet, stable, stability_method, stability_warning = _floquet(hb, system, branch, progress)
    t_stab = clock()

    speed_rpm = rad_s_to_rpm(np.asarray(branch.p))
    speed_rpm[0] = sw.speed_rpm_start  # exact ends (no rpm -> rad/s -> rpm rounding)
    if branch.success:
        speed_rpm[-1] = sw.speed_rpm_stop
    summaries = [PeriodicSolution.from_z(model, p, z, hb, residual_norm=r, iterations=it).summary()
                 for p, z, r, it in zip(branch.p, branch.z, branch.residual, branch.iterations)]
    table = np.column_stack([
        speed_rpm,
        np.asarray(branch.p) * model.teeth_pinion / (2 * math.pi),
        [s["dte_mean_um"] for s in summaries],
        [s["dte_rms_um"] for s in summaries],
        [s["dte_p2p_um"] for s in summaries],
        [s["dynamic_factor"] for s in summaries],
        floquet,
        stable,
        np.full(len(branch), nu),
        branch.residual,
    ]).reshape(len(branch), len(COLUMNS))
    rows = [[*row[:8], int(nu), row[9]] for row in table]
    for row in rows:
        if not math.isnan(row[7]):
            row[7] = int(row[7])
    write_csv_atomic(out_dir / "frc.csv", COLUMNS, rows)

    folds = branch.folds
    fold_info = [
        {"index": int(i), "speed_rpm": float(speed_rpm[i]), "mesh_freq_hz": float(table[i, 1]),
         "dte_rms_um": float(table[i, 3]), "dte_p2p_um": float(table[i, 4]),
         "kind": "maximum speed" if branch.tangent_p[i - 1] > 0 else "minimum speed"}
        for i in folds
    ]
    title = (f"{model.coupling} {model.formulation}, {model.boundary}, H={harmonics}, nu={nu}: "
             f"{len(branch)} points, {len(folds)} folds" + ("" if branch.success else f" [{branch.status.name}]"))
    fig = plot_frc(speed_rpm, table[:, 3], table[:, 4], stable, folds, title)
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
            "criterion": "hbgear.stability.is_stable: all |multipliers| <= 1 + 1e-9 (trivial ones removed); "
            "max_abs_floquet is over the base period (nu mesh periods)",
            "unstable_points": int(np.sum(stable == 0)),
        },
        "continuation": asdict(method) | {"method": "pseudo-arclength", "parameter": "pinion speed [rad/s]"},
        "model": {"coupling": model.coupling, "formulation": model.formulation, "boundary": model.boundary,
                  "contact": model.contact, "friction_law": repr(model.friction), "ndof": model.ndof},
        "timings_s": {
            "start_solution": t_start - t0,
            "compile": t_compile - t_start,
            "continuation": t_cont - t_compile,
            "per_point_ms": 1e3 * (t_cont - t_compile) / n_steps,
            "stability": t_stab - t_cont,
            "outputs": t_out - t_stab,
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
    peak = summary["peak"]
    print(
        f"frc: {len(branch)} points from {sw.speed_rpm_start:g} to {sw.speed_rpm_stop:g} rpm (H={harmonics}, nu={nu}); "
        f"peak DTE p2p {peak['dte_p2p_um']:.4g} um at {peak['speed_rpm']:.6g} rpm; "
        f"{len(summary['fold_speeds_rpm'])} folds; {summary['stability']['unstable_points']} unstable points; "
        f"{summary['timings_s']['total']:.1f} s -> {out_dir}"
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
