"""`hbgear simulate CONFIG --speed RPM [--cycles N]`: time integration to steady state.

Writes into the output directory (INTERFACE.md), all through :mod:`hbgear.io`:

- `summary.json`: `speed_rpm`, the :data:`hbgear.metrics.SUMMARY_KEYS`, `cycles_integrated`,
  `period_mesh_cycles`, `steady_measure`, `output_torque_Nm` (``"reaction"`` boundary: the mean
  output torque fixed by periodicity), the integrator settings, a model description and the
  configuration (TOML keys and units);
- `timeseries.csv`: the last recorded steady cycles on a uniform grid -- `time_s, mesh_phase,
  dte_um, dte_velocity_m_per_s, mesh_force_N` and, per pair slot ``k`` (``pair1`` entered at
  the start of the current mesh period, ``pair2`` one period earlier), `pairK_normal_load_N,
  pairK_mu, pairK_friction_force_N, pairK_sliding_velocity_m_per_s`;
- `timeseries.png`: DTE, mesh force and per-pair normal and friction forces.
"""

from __future__ import annotations

import math

import numpy as np

from ..build import build_model
from ..cli import Command, positive_float, positive_int, register
from ..io import save_figure_atomic, write_csv_atomic, write_json_atomic
from ..model import PAIR_SLOTS
from ..simulate import simulate

__all__ = ["SIMULATE", "run", "timeseries_table", "plot_timeseries"]


def add_arguments(parser) -> None:
    parser.add_argument(
        "--speed", required=True, type=positive_float("--speed", "a positive pinion speed in rpm"),
        metavar="RPM", help="pinion speed [rpm]",
    )
    parser.add_argument(
        "--cycles", type=positive_int("--cycles", "a positive number of mesh cycles"), default=None,
        metavar="N", help="maximum number of mesh cycles to integrate (default: [simulate] cycles)",
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


def timeseries_table(res):
    """Header and rows of `timeseries.csv` from a :class:`~hbgear.simulate.TimeResponse`."""
    header = ["time_s", "mesh_phase", "dte_um", "dte_velocity_m_per_s", "mesh_force_N"]
    columns = [res.t, res.s, 1e6 * res.q[0], res.qd[0], res.mesh_force]
    for k in range(PAIR_SLOTS):
        header += [
            f"pair{k + 1}_normal_load_N",
            f"pair{k + 1}_mu",
            f"pair{k + 1}_friction_force_N",
            f"pair{k + 1}_sliding_velocity_m_per_s",
        ]
        columns += [res.pairs["normal"][k], res.pairs["mu"][k], res.pairs["friction"][k], res.pairs["vs"][k]]
    return header, np.column_stack(columns)


def plot_timeseries(res):
    """Figure: DTE; mesh force and per-pair normal loads; per-pair friction forces."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    t_ms = 1e3 * res.t
    fig, axes = plt.subplots(3, 1, figsize=(8, 8), sharex=True)
    axes[0].plot(t_ms, 1e6 * res.q[0], color="k")
    axes[0].set_ylabel("DTE [um]")
    axes[1].plot(t_ms, res.mesh_force, color="k", label="mesh force")
    contact = res.pairs["sigma"] > 0
    for k in range(PAIR_SLOTS):
        axes[1].plot(t_ms, np.where(contact[k], res.pairs["normal"][k], np.nan), label=f"pair {k + 1} normal load")
        axes[2].plot(t_ms, np.where(contact[k], res.pairs["friction"][k], np.nan), label=f"pair {k + 1}")
    axes[1].set_ylabel("force [N]")
    axes[2].set_ylabel("friction force [N]")
    axes[2].set_xlabel("time [ms]")
    for ax in axes[1:]:
        ax.legend(fontsize=8, loc="upper right")
    for ax in axes:
        ax.grid(alpha=0.3)
    fig.suptitle(
        f"{res.speed_rpm:.6g} rpm: steady state after {res.cycles} mesh cycles "
        f"(period {res.period_cycles} mesh cycle{'s' if res.period_cycles > 1 else ''})"
    )
    fig.tight_layout()
    return fig


def run(config, args, out_dir) -> int:
    model = build_model(config)
    sim = config.simulate
    cycles = args.cycles if args.cycles is not None else sim.cycles
    res = simulate(
        model,
        args.speed * math.pi / 30.0,
        max_cycles=max(int(cycles), 2),
        rtol=sim.rtol,
        atol=sim.atol_m,
        steady_tolerance=sim.steady_tolerance,
    )
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
    header, rows = timeseries_table(res)
    write_csv_atomic(out_dir / "timeseries.csv", header, rows)
    fig = plot_timeseries(res)
    try:
        save_figure_atomic(fig, out_dir / "timeseries.png", dpi=120)
    finally:
        import matplotlib.pyplot as plt

        plt.close(fig)
    write_json_atomic(out_dir / "summary.json", summary)
    return 0


SIMULATE = register(
    Command(
        name="simulate",
        help="time integration to steady state at one speed (summary.json, timeseries.csv/.png)",
        add_arguments=add_arguments,
        run=run,
    )
)
