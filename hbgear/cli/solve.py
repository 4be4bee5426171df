"""``hbgear solve CONFIG --speed RPM``: one periodic solution by harmonic balance.

Writes ``solution.json`` (read-outs, powers, Floquet multipliers, solver facts, config),
``harmonics.csv`` (DTE amplitude and phase per mesh order, half orders when nu = 2) and
``waveform.csv`` (one base period: DTE, mesh force, per-pair loads and friction).
"""

from __future__ import annotations

from . import Command, register
from .common import add_speed_argument, solution_record, solve_config

__all__ = ["run", "waveform_header", "waveform_rows"]


def waveform_header(pair_slots: int) -> list[str]:
    """Columns of ``waveform.csv``: pair ``k`` entered contact ``k - 1`` mesh periods before the
    current one (the same names as simulate's ``timeseries.csv``)."""
    header = ["time_s", "mesh_phase", "dte_um", "dte_velocity_m_per_s", "mesh_force_N"]
    for j in range(1, pair_slots + 1):
        header += [f"pair{j}_normal_load_N", f"pair{j}_mu", f"pair{j}_friction_force_N",
                   f"pair{j}_sliding_velocity_m_per_s"]
    return header


def waveform_rows(solution, points: int, pair_slots: int):
    """Rows of ``waveform.csv`` over one base period."""
    import numpy as np

    model = solution.model
    fraction = np.linspace(0.0, 1.0, points, endpoint=False)
    q, qd = solution.state_on_grid(points)
    s = np.mod(fraction * solution.nu, 1.0)
    period = 2 * np.pi / solution.base_frequency
    mesh = model.mesh_force(s, q, qd, solution.omega_pinion)
    pairs = model.pair_friction(s, q, qd, solution.omega_pinion)
    columns = [fraction * period, s, 1e6 * q[0], qd[0], mesh]
    for k in range(pair_slots):
        columns += [pairs["normal"][k] * (pairs["sigma"][k] > 0), pairs["mu"][k], pairs["friction"][k], pairs["vs"][k]]
    # whole columns to Python floats at once (16 H rows at many harmonics)
    yield from zip(*(np.asarray(c, dtype=float).tolist() for c in columns))


def run(config, args, out_dir) -> int:
    from ..build import build_model
    from ..gear.model import PAIR_SLOTS
    from ..outputs.io import write_csv_atomic, write_json_atomic

    solution = solve_config(config, build_model(config), args.speed)
    record = solution_record(solution) | {"config": config.to_dict()}
    if solution.model.bearings is None:
        write_csv_atomic(out_dir / "harmonics.csv", ["mesh_order", "dte_amplitude_um", "dte_phase_deg"],
                         solution.harmonic_table())
    else:  # the bearing forces' amplitudes per order as further columns
        write_csv_atomic(out_dir / "harmonics.csv", *solution.bearing_harmonic_table())
    write_csv_atomic(out_dir / "waveform.csv", waveform_header(PAIR_SLOTS),
                     waveform_rows(solution, max(512, 8 * solution.harmonics), PAIR_SLOTS))
    write_json_atomic(out_dir / "solution.json", record)
    print(f"{args.speed:g} rpm: DTE rms {record['dte_rms_um']:.4g} um, p2p {record['dte_p2p_um']:.4g} um, "
          f"max|Floquet| {record['max_abs_floquet']:.6f} (H={solution.harmonics}, nu={solution.nu}) -> {out_dir}")
    return 0


register(Command("solve", "one periodic solution by harmonic balance", add_speed_argument, run))
