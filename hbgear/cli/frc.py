"""``hbgear frc CONFIG``: frequency-response curve by arclength continuation over ``[sweep]``.

Load -> build -> :func:`hbgear.frequency_response` -> write, into the output directory:

- ``frc.csv``: :data:`COLUMNS`, one row per continuation point in path order (a fold shows as the
  speed going back; located folds are rows of their own), then the rows of every period-doubled
  branch (``nu = 2``), each in path order from its bifurcation;
- ``floquet.csv``: every Floquet multiplier of every ``nu = 1`` point (not with ``--no-stability``);
- ``orders.csv``: per ``frc.csv`` row, the DTE amplitude at mesh orders 1..K (``[sweep] orders``,
  default ``min(H / nu, 10)``) and, when there are ``nu = 2`` rows, at the half orders
  (:meth:`~hbgear.gear.response.GearFrequencyResponse.order_rows`);
- ``frc.json``: status and message, ``H`` and how it was chosen, folds, stability (method,
  unstable points, the exact scan's unstable zones), period doublings, continuation settings,
  the mesh orders, the ISO 6336-1 resonance speed ``n_E1`` and its ranges, the points of
  ``floquet.png``, timings (``outputs``: the CSV files; ``total``: up to this file), the config;
- ``modes.json`` and ``campbell.png``: the natural frequencies of the mean-stiffness model
  (:func:`hbgear.natural_frequencies`) and the Campbell diagram (mesh orders against speed);
- on bearings, ``frc.csv`` and ``orders.csv`` gain the bearing forces, ``bearing_forces.png``
  shows their RMS (LOA, OLOA) against speed and ``bearing_orders_<gear>_<direction>.png`` each
  force's order tracking (as ``orders.png``, in N);
- the figures, drawn last, once the numbers are on disk, shared between this process and a
  helper process started with the command (:class:`hbgear.outputs.drawing.FigureDrawer`; it
  imports matplotlib while the curve runs):
  ``frc.png`` the curve (:func:`hbgear.outputs.plots.frc_figure`); ``orders.png`` order tracking
  (order lines and the speed x order map); ``dynamic_factor.png`` ``max F_mesh / N`` with ``n_E1``
  and its ranges; ``floquet.png`` the multipliers of a few selected points on the unit circle
  (not with ``--no-stability``).

If the continuation stops before the stop speed, the curve so far is written (with the status in
``frc.json``) and the run ends with exit status 1.
"""

from __future__ import annotations

import sys
import time

from . import Command, register

__all__ = ["FRC", "period_doubling_enabled", "run"]


def add_arguments(parser) -> None:
    parser.add_argument("--no-progress", action="store_true", help="no progress bar (default: only on a terminal)")
    parser.add_argument("--no-stability", action="store_true", help="skip the Floquet multipliers (columns NaN)")
    pd = parser.add_mutually_exclusive_group()
    pd.add_argument("--no-period-doubling", dest="period_doubling", action="store_const", const=False, default=None,
                    help="do not look for period doublings nor follow the nu = 2 branches")
    pd.add_argument("--period-doubling", dest="period_doubling", action="store_const", const=True,
                    help="follow the nu = 2 branches even where the default cost rule would skip them")


def _period_doubling_flag(config, args):
    """``(flag, source)``: ``--period-doubling`` / ``--no-period-doubling``, else ``sweep.period_doubling``."""
    flag = getattr(args, "period_doubling", None)
    if flag is not None:
        return flag, "--period-doubling / --no-period-doubling"
    return getattr(config.sweep, "period_doubling", None), "sweep.period_doubling"


def period_doubling_enabled(config, args, model, harmonics, nu) -> tuple[bool, bool, str]:
    """``(locate?, follow?, why)`` for this run (:func:`hbgear.gear.response.period_doubling_rule`)."""
    from ..gear.response import period_doubling_rule

    flag, source = _period_doubling_flag(config, args)
    locate, follow, why = period_doubling_rule(model, harmonics, nu, flag)
    return locate, follow, f"{why} ({source})" if why in ("on", "off") else why


def validate(config, args) -> None:
    """``sweep.orders`` within the harmonics of the config (checked before anything runs)."""
    from ..errors import ConfigError

    orders, so = config.sweep.orders, config.solver
    if orders is not None and so.harmonics is not None and orders * so.subharmonic > so.harmonics:
        raise ConfigError("sweep.orders", orders, f"an integer <= solver.harmonics / solver.subharmonic = "
                          f"{so.harmonics // so.subharmonic} (mesh orders beyond it are not in the solution)")


def _order_count(config, curve) -> tuple[int | None, str]:
    """``(K or None for the default, how it was chosen)``: ``sweep.orders``, capped at ``H // nu``
    when ``H`` was chosen automatically."""
    from ..gear.response import DEFAULT_ORDERS

    limit = curve.harmonics // curve.response.hb.nu
    requested = config.sweep.orders
    if requested is None:
        return None, f"default: min(H // nu, {DEFAULT_ORDERS})"
    if requested > limit:
        return limit, f"sweep.orders = {requested} capped at H // nu = {limit} (H chosen automatically)"
    return requested, "sweep.orders"


def _summary(curve, config, args, method_options, timings, orders=None) -> dict:
    """The ``frc.json`` record of a curve."""
    import numpy as np

    r, model, so = curve.response, curve.model, config.solver
    stab = r.stability
    pd_rule = curve.period_doubling_rule
    if pd_rule in ("on", "off"):
        pd_rule += f" ({_period_doubling_flag(config, args)[1]})"
    unstable = int((curve.stable[:curve.points] == 0).sum())
    peak = int(curve.dte_p2p_um[:curve.points].argmax()) if curve.points else 0
    return {
        "command": "frc", "status": r.status.name.lower(), "success": curve.success, "message": r.message,
        "speed_rpm_start": curve.speed_rpm_range[0], "speed_rpm_stop": curve.speed_rpm_range[1],
        "speed_rpm_reached": float(curve.speed_rpm[curve.points - 1]) if curve.points else None,
        "harmonics": r.hb.harmonics, "harmonics_rule": curve.harmonics_rule, "nu": r.hb.nu,
        "time_samples": r.hb.samples, "points": curve.points, "rejected_steps": r.branch.rejected,
        "max_residual": float(r.branch.residual.max()) if curve.points else None, "tolerance": so.tolerance,
        "folds": curve.fold_records, "fold_speeds_rpm": [f["speed_rpm"] for f in curve.fold_records],
        "peak": {"speed_rpm": float(curve.speed_rpm[peak]), "dte_p2p_um": float(curve.dte_p2p_um[peak]),
                 "dte_rms_um": float(curve.dte_rms_um[peak])},
        "stability": {
            "available": stab is not None and bool(np.all(np.isfinite(curve.max_abs_floquet[:curve.points]))),
            "method": None if stab is None else stab.method,
            "warning": "Floquet multipliers skipped (--no-stability)" if stab is None else stab.warning,
            "criterion": "hbgear.engine.floquet.stable_verdict: all |multipliers| <= 1 + 1e-9 (trivial ones removed; "
                         "the spring boundary's neutral soft-mode pair, within 1e-5 of exp(+-i w_b T), excluded); "
                         "max_abs_floquet is over the base period (nu mesh periods), all multipliers",
            "unstable_points": unstable, "unstable_zones": curve.unstable_zones,
            "unstable_zones_rule": curve.zones_rule,
        },
        "period_doubling_rule": pd_rule, "period_doubling": curve.period_doublings,
        "orders": orders, "iso6336_resonance": curve.resonance.as_dict(),
        "floquet_points": [] if stab is None else curve.floquet_points(),
        "continuation": method_options | {"method": "pseudo-arclength", "parameter": "pinion speed [rad/s]"},
        "model": {"coupling": model.coupling, "formulation": model.formulation, "boundary": model.boundary,
                  "contact": model.contact, "friction_law": repr(model.friction), "ndof": model.ndof,
                  "coordinates": list(model.layout.coordinates)},
        "timings_s": timings, "programs": _programs(), "config": config.to_dict(),
    }


def _programs() -> dict:
    """Where the traced programs are kept and how many this run loaded, exported or traced
    (:func:`hbgear.engine.persistent.stats`): a warm run loads and exports none."""
    from ..engine import persistent

    return persistent.stats()


def _report(curve, out_dir, seconds) -> None:
    """The one-line summary on stdout, and a warning per failed period-doubling branch on stderr."""
    for r in curve.period_doublings:
        if r["status"] == "failed":
            print(f"frc: warning: period doubling near {r.get('speed_rpm', r['bracket_rpm'][0]):.6g} rpm: "
                  f"{r['message']} (nu = 1 curve and frc.json written)", file=sys.stderr)
    n = curve.points
    peak = int(curve.dte_p2p_um[:n].argmax())
    zones, located = curve.unstable_zones, [r for r in curve.period_doublings if "speed_rpm" in r]
    zones_text = ""
    if zones:
        hidden = sum(z["between_curve_points"] for z in zones)
        zones_text = (f"{len(zones)} unstable zone(s) by the fine exact scan"
                      + (f", {hidden} between curve points" if hidden else "") + "; ")
    pd_text = ""
    if located:
        followed = [r for r in located if r["points"] > 0]
        speeds = ", ".join(f"{r['speed_rpm']:.6g}" for r in located)
        pd_text = (f"period doubling at {speeds} rpm "
                   f"({len(followed)} nu = 2 branches followed, {sum(r['points'] for r in followed)} points); ")
    start, stop = curve.speed_rpm_range
    print(f"frc: {n} points from {start:g} to {stop:g} rpm (H={curve.harmonics}, nu={curve.response.hb.nu}); "
          f"peak DTE p2p {curve.dte_p2p_um[peak]:.4g} um at {curve.speed_rpm[peak]:.6g} rpm; {len(curve.folds)} folds; "
          f"{int((curve.stable[:n] == 0).sum())} unstable points; {zones_text}{pd_text}{seconds:.1f} s -> {out_dir}")


def run(config, args, out_dir) -> int:
    from ..engine.prefetch import import_in_background
    from ..outputs.drawing import FigureDrawer

    t0 = time.perf_counter()
    drawer = FigureDrawer(("hbgear.api",))  # a second process for the figures, importing while the curve runs
    import_in_background("matplotlib.figure", "matplotlib.backends.backend_agg")  # the figures, drawn last
    with drawer:
        return _run(config, args, out_dir, drawer, t0)


def _run(config, args, out_dir, drawer, t0) -> int:
    from dataclasses import asdict

    from ..api import frc_curve
    from ..engine.continuation import sweep_method
    from ..errors import ConvergenceError
    from ..gear.response import FLOQUET_COLUMNS
    from ..gear.solve import rpm_to_rad_s
    from ..outputs.drawing import FigureJob
    from ..outputs.io import write_csv_atomic, write_json_atomic

    so, sw = config.solver, config.sweep
    flag, _ = _period_doubling_flag(config, args)
    curve = frc_curve(config, stability=not args.no_stability, period_doubling=flag,
                      progress=False if args.no_progress else None)
    t_done = time.perf_counter()
    count, order_rule = _order_count(config, curve)
    orders = curve.mesh_orders(count)
    modes = curve.natural_frequencies()
    png = {"dpi": 120}
    jobs = [FigureJob(curve.plot, (), {}, out_dir / "frc.png", png),
            FigureJob(curve.plot_orders, (orders,), {}, out_dir / "orders.png", png),
            FigureJob(curve.plot_dynamic_factor, (), {}, out_dir / "dynamic_factor.png", png),
            FigureJob(curve.plot_campbell, (max(int(orders.max()), 1),), {}, out_dir / "campbell.png", png)]
    if curve.model.bearings is not None:
        from ..gear.readouts import BEARING_FORCES
        from ..outputs.plots import bearing_forces_figure

        jobs.append(FigureJob(bearing_forces_figure, (curve,), {"modes": modes}, out_dir / "bearing_forces.png", png))
        amplitudes = curve.bearing_order_amplitudes_N(orders)  # once for the four figures
        jobs += [FigureJob(curve.plot_bearing_orders, (name, orders), {"amplitudes_N": amplitudes},
                           out_dir / f"bearing_orders_{name}.png", png) for name in BEARING_FORCES]
    if curve.response.stability is not None:
        jobs.append(FigureJob(curve.plot_floquet, (), {}, out_dir / "floquet.png", png))
    drawer.start(jobs)  # the helper draws while this process writes the tables
    write_csv_atomic(out_dir / "frc.csv", curve.columns, [[row[c] for c in curve.columns] for row in curve.rows()])
    if curve.response.stability is not None:
        write_csv_atomic(out_dir / "floquet.csv", FLOQUET_COLUMNS, curve.floquet_rows())
    write_csv_atomic(out_dir / "orders.csv", *curve.order_rows(orders))
    method = sweep_method(rpm_to_rad_s(sw.speed_rpm_start), rpm_to_rad_s(sw.speed_rpm_stop),
                          None if sw.step_rpm is None else rpm_to_rad_s(sw.step_rpm))
    t_out = time.perf_counter()
    timings = dict(curve.timings_s) | {"per_point_ms": 1e3 * curve.timings_s["continuation"] / max(curve.points - 1, 1),
                                       "outputs": t_out - t_done, "total": t_out - t0}
    write_json_atomic(out_dir / "frc.json", _summary(curve, config, args, asdict(method), timings,
                                                     {"mesh_orders": orders, "rule": order_rule}))
    write_json_atomic(out_dir / "modes.json", {"model": "mean mesh stiffness, no friction, undamped",
                                               "modes": modes.records(float(curve.model.teeth_pinion), (1, 2, 3))})
    drawer.finish()
    if not curve.success:
        raise ConvergenceError(
            f"frc continuation from {sw.speed_rpm_start:g} to {sw.speed_rpm_stop:g} rpm (H={curve.harmonics}, "
            f"nu={so.subharmonic}) stopped at {curve.speed_rpm[curve.points - 1]:.6g} rpm: {curve.response.message}. "
            f"{_corner_hint(curve.model)}The partial curve ({curve.points} points) was written to {out_dir / 'frc.csv'} with the status in frc.json")
    _report(curve, out_dir, time.perf_counter() - t0)
    return 0


def _corner_hint(model) -> str:
    """Why a relieved per-pair model with formulation A may stop (README, Limitations), or ``""``."""
    if not (model.pairs_may_open and model.formulation == "A"
            and model.normal_loads == "compressive" and model.friction.name != "none"):
        return ""
    return ("With formulation A a pair's friction load (its static load) switches off at a finite value where the "
            "pair opens, so where a contact loss is born the residual is not differentiable (a corner of the curve, "
            "README 'Limitations'). ")


FRC = register(Command(name="frc", help="frequency-response curve by arc-length continuation over [sweep] "
                       "(frc.csv/.json/.png, orders.csv/.png, dynamic_factor.png, floquet.png)",
                       add_arguments=add_arguments, run=run, validate=validate))
