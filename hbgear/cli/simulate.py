"""`hbgear simulate CONFIG --speed RPM [--cycles N] [--march]`: time integration to steady state.

Writes into the output directory (INTERFACE.md), all through :mod:`hbgear.outputs.io`:

- `summary.json`: `speed_rpm`, the :data:`hbgear.gear.readouts.SUMMARY_KEYS`, `cycles_integrated`,
  `period_mesh_cycles`, `steady_measure`, `output_torque_Nm` (``"reaction"`` boundary: the mean
  output torque fixed by periodicity), the integrator settings, a model description and the
  configuration (TOML keys and units);
- `timeseries.csv`: the last recorded steady cycles on a uniform grid -- `time_s, mesh_phase,
  dte_um, dte_velocity_m_per_s, mesh_force_N` and, per pair slot ``k`` (``pair1`` entered at
  the start of the current mesh period, ``pair2`` one period earlier), `pairK_normal_load_N,
  pairK_mu, pairK_friction_force_N, pairK_sliding_velocity_m_per_s`;
- `timeseries.png`: DTE, mesh force and per-pair normal and friction forces.

With `--march` exactly `--cycles` mesh cycles are integrated from the static state with no
steady-state test (:func:`hbgear.gear.simulate.march`: transients, growth in unstable zones): the
summary keys are then means over the last cycle (`"mode": "march"`, plus
`dte_p2p_growth_per_cycle` over the last up to 20 cycles), the time series holds the last two
cycles, and `cycles.csv` the per-cycle `cycle, dte_mean_um, dte_rms_um, dte_p2p_um`.
"""

from __future__ import annotations

import math

from . import Command, positive_float, positive_int, register

__all__ = ["SIMULATE", "run", "timeseries_table"]


def add_arguments(parser) -> None:
    parser.add_argument(
        "--speed", required=True, type=positive_float("--speed", "a positive pinion speed in rpm"),
        metavar="RPM", help="pinion speed [rpm]",
    )
    parser.add_argument(
        "--cycles", type=positive_int("--cycles", "a positive number of mesh cycles"), default=None,
        metavar="N", help="maximum number of mesh cycles to integrate (default: [simulate] cycles)",
    )
    parser.add_argument(
        "--march", action="store_true",
        help="integrate exactly --cycles mesh cycles, no steady-state test (writes cycles.csv too)",
    )


def model_description(model) -> dict:
    """The structural choices and key constants of a model, for provenance."""
    return {
        "coupling": model.coupling,
        "formulation": model.formulation,
        "boundary": model.boundary,
        "contact": model.contact,
        "damping_model": model.damping_model,
        "friction_law": repr(model.friction),
        "contact_ratio": float(model.contact_ratio),
        "k_max_N_per_m": float(model.k_max_N_per_m),
        "k_min_N_per_m": float(model.k_min_N_per_m),
        "k_mean_N_per_m": float(model.k_mean_N_per_m),
        "mass_equivalent_kg": float(model.mass_equivalent_kg),
        "mesh_damping_Ns_per_m": float(model.mesh_damping_Ns_per_m),
        "normal_load_N": float(model.normal_load_N),
    }


def timeseries_table(res, pair_slots: int):
    """Header and rows of `timeseries.csv` from a :class:`~hbgear.gear.simulate.TimeResponse`."""
    import numpy as np

    header = ["time_s", "mesh_phase", "dte_um", "dte_velocity_m_per_s", "mesh_force_N"]
    columns = [res.t, res.s, 1e6 * res.q[0], res.qd[0], res.mesh_force]
    for k in range(pair_slots):
        header += [f"pair{k + 1}_normal_load_N", f"pair{k + 1}_mu", f"pair{k + 1}_friction_force_N",
                   f"pair{k + 1}_sliding_velocity_m_per_s"]
        columns += [res.pairs["normal"][k], res.pairs["mu"][k], res.pairs["friction"][k], res.pairs["vs"][k]]
    return header, np.column_stack(columns)


def _last_cycles(model, rec, count: int = 2):
    """The last `count` cycles of a :class:`~hbgear.gear.simulate.MarchRecord` as the fields
    :func:`timeseries_table` and :func:`hbgear.outputs.plots.timeseries_figure` read."""
    from types import SimpleNamespace

    import numpy as np

    count = min(count, rec.cycles)
    first = rec.first_cycle + rec.cycles - count
    s = np.concatenate([rec.s] * count)
    t = np.concatenate([(first + k + rec.s) * rec.mesh_period_s for k in range(count)])
    q = np.concatenate(list(rec.q[-count:]), axis=1)
    qd = np.concatenate(list(rec.qd[-count:]), axis=1)
    omega = rec.omega_pinion
    pairs = {k: np.asarray(v) for k, v in model.pair_friction(s, q, qd, omega).items()}
    return SimpleNamespace(t=t, s=s, q=q, qd=qd, mesh_force=np.asarray(model.mesh_force(s, q, qd, omega)), pairs=pairs,
                           speed_rpm=rec.speed_rpm)


def run_march(config, args, out_dir, model, cycles) -> int:
    """`--march`: exactly `cycles` mesh cycles from the static state (see the module docstring)."""
    import numpy as np

    from ..gear.simulate import march
    from ..outputs.io import write_csv_atomic

    sim = config.simulate
    rec = march(model, args.speed * math.pi / 30.0, int(cycles), rtol=sim.rtol, atol=sim.atol_m)
    window = min(20, rec.cycles - 1)
    growth = float((rec.dte_p2p_um[-1] / rec.dte_p2p_um[-1 - window]) ** (1.0 / window)) if window > 0 else float("nan")
    summary = {"speed_rpm": args.speed, "mesh_freq_hz": args.speed / 60.0 * model.teeth_pinion, "mode": "march"}
    summary |= rec.last_summary
    if model.boundary == "reaction":
        summary["output_torque_Nm"] = float(rec.reaction_force_N[-1]) * float(model.base_radius_gear_m)
    summary |= {
        "cycles_integrated": rec.cycles,
        "dte_p2p_growth_per_cycle": growth,
        "integrator": {"method": rec.method, "rtol": sim.rtol, "atol_m": sim.atol_m, "cycles": int(cycles)},
        "elapsed_s": rec.elapsed_s,
        "model": model_description(model) | {"friction_law_integrated": repr(rec.friction_law),
                                              "u_static_m": rec.u_static},
        "config": config.to_dict(),
    }
    write_csv_atomic(out_dir / "cycles.csv", ["cycle", "dte_mean_um", "dte_rms_um", "dte_p2p_um"],
                     np.column_stack([rec.first_cycle + np.arange(rec.cycles), rec.dte_mean_um, rec.dte_rms_um,
                                      rec.dte_p2p_um]))
    last = _last_cycles(model, rec)
    _write_outputs(out_dir, last, summary, title=f"{rec.speed_rpm:.6g} rpm: last cycles of {rec.cycles} from the "
                                                 f"static state (p2p growth {growth:.4f} per cycle)")
    return 0


def _write_outputs(out_dir, record, summary, title=None) -> None:
    """`timeseries.csv`, `timeseries.png` and `summary.json` of a run (steady state or march)."""
    from ..gear.model import PAIR_SLOTS
    from ..outputs.io import save_figure_atomic, write_csv_atomic, write_json_atomic
    from ..outputs.plots import timeseries_figure

    header, rows = timeseries_table(record, PAIR_SLOTS)
    write_csv_atomic(out_dir / "timeseries.csv", header, rows)
    save_figure_atomic(timeseries_figure(record, PAIR_SLOTS, title=title), out_dir / "timeseries.png", dpi=120)
    write_json_atomic(out_dir / "summary.json", summary)


def run(config, args, out_dir) -> int:
    from ..build import build_model
    from ..errors import ConvergenceError
    from ..gear.simulate import simulate

    model = build_model(config)
    sim = config.simulate
    cycles = args.cycles if args.cycles is not None else sim.cycles
    if getattr(args, "march", False):
        return run_march(config, args, out_dir, model, cycles)
    try:
        res = simulate(model, args.speed * math.pi / 30.0, max_cycles=max(int(cycles), 2), rtol=sim.rtol,
                       atol=sim.atol_m, steady_tolerance=sim.steady_tolerance)
    except ConvergenceError as error:
        raise ConvergenceError(f"{error} (allow more cycles: --cycles / simulate.cycles)") from None
    summary = {"speed_rpm": args.speed, "mesh_freq_hz": args.speed / 60.0 * model.teeth_pinion}
    summary |= res.summary
    if model.boundary == "reaction":  # the output torque periodicity fixed
        summary["output_torque_Nm"] = res.reaction_force_N * float(model.base_radius_gear_m)
    summary |= {
        "cycles_integrated": res.cycles,
        "period_mesh_cycles": res.period_cycles,
        "steady_measure": res.steady_measure,
        "integrator": {"method": res.method, "rtol": sim.rtol, "atol_m": sim.atol_m,
                       "steady_tolerance": sim.steady_tolerance, "max_cycles": cycles},
        "elapsed_s": res.elapsed_s,
        "model": model_description(model) | {"friction_law_integrated": repr(res.friction_law),
                                              "u_static_m": res.u_static},
        "config": config.to_dict(),
    }
    _write_outputs(out_dir, res, summary)
    return 0


SIMULATE = register(
    Command(
        name="simulate",
        help="time integration to steady state at one speed (summary.json, timeseries.csv/.png); "
             "--march: a fixed number of cycles",
        add_arguments=add_arguments,
        run=run,
    )
)
