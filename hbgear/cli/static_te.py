"""``hbgear static-te CONFIG [--torque NM ...]``: loaded static transmission error, Harris map.

At each pinion torque (default ``[load] torque_pinion_Nm``; repeated ``--torque`` flags add
torques) and each of the mesh phases, the quasi-static TE ``delta_s`` solves
``sum_j k_j max(delta_s - eps - e_j, 0) = N``, ``N = T_p / R_bp`` (MODEL.md section 9;
:func:`hbgear.gear.contact.loaded_te_table`). With the rectangular ``k(t)`` this is
``eps + N/k(s)``.

Writes ``static_te.csv`` (one row per torque and phase), ``static_te.json`` (per-torque
summary, geometry, config) and ``static_te.png``; with several torques also ``harris.csv``
and ``harris.png`` (TE peak-to-peak against torque).
"""

from __future__ import annotations

import math


from . import Command, positive_float, register
from ..errors import ConfigError

HARRIS_HEADER = ["torque_pinion_Nm", "loaded_te_p2p_um"]


def add_arguments(parser) -> None:
    parser.add_argument(
        "--torque",
        type=positive_float("--torque", "a positive pinion torque in N m"),
        action="append",
        metavar="NM",
        help="pinion torque [N m]; repeat for a Harris map (default: [load] torque_pinion_Nm)",
    )


def torques_of(config, args) -> list[float]:
    """The torques of the run, in the order given (each once)."""
    torques = list(args.torque) if args.torque else [config.load.torque_pinion_Nm]
    for i, torque in enumerate(torques):
        if torque in torques[:i]:
            raise ConfigError("--torque", torque, "each torque once")
    return torques


def contacts_of(config, torques):
    """One :class:`~hbgear.build.ToothContact` per torque, on one geometry."""
    from ..build import build_geometry, build_tooth_contact

    geometry = build_geometry(config.gear)
    return [build_tooth_contact(config, torque, geometry) for torque in torques]


def validate(config, args) -> None:
    contacts_of(config, torques_of(config, args))


def static_te_header(slots: int) -> list[str]:
    """Columns of ``static_te.csv``; pair ``j`` entered contact ``j - 1`` mesh periods before the
    current one (as in ``waveform.csv``)."""
    pairs = range(1, slots + 1)
    return (["torque_pinion_Nm", "mesh_phase", "position_mm", "loaded_te_um", "mesh_stiffness_MN_per_m"]
            + [f"pair_load_N_{j}" for j in pairs] + [f"pair_stiffness_MN_per_m_{j}" for j in pairs])


def static_te_rows(table):
    """Rows of ``static_te.csv``: every phase of every torque; ``position_mm`` is pair 1's
    position along the line of action from the start of active contact."""
    for i, torque in enumerate(table.torque_pinion_Nm):
        for n, phase in enumerate(table.phase):
            yield [torque, phase, 1e3 * table.position_m[0, n], 1e6 * table.delta_m[i, n],
                   1e-6 * table.mesh_stiffness_N_per_m[i, n], *table.pair_loads_N[i, :, n],
                   *(1e-6 * table.pair_stiffness_N_per_m[i, :, n])]


def torque_record(table, i: int, contact) -> dict:
    """``static_te.json`` summary of torque `i`."""
    record = {
        "torque_pinion_Nm": table.torque_pinion_Nm[i],
        "normal_load_N": table.load_N[i],
        "loaded_te_p2p_um": 1e6 * table.p2p_m[i],
        "loaded_te_mean_um": 1e6 * table.mean_m[i],
        "mesh_stiffness_mean_MN_per_m": 1e-6 * table.mesh_stiffness_mean_N_per_m[i],
        "pair_stiffness_max_MN_per_m": 1e-6 * table.pair_stiffness_max_N_per_m[i],
    }
    if contact.iso6336 is not None:
        record |= {
            "iso6336_c_prime_N_per_mm_um": contact.iso6336.c_prime_N_per_mm_um,
            "iso6336_c_gamma_alpha_N_per_mm_um": contact.iso6336.c_gamma_alpha_N_per_mm_um,
            "iso6336_line_load_factor": contact.iso6336.line_load_factor,
        }
    return record


def geometry_record(pair) -> dict:
    """The derived geometry a relief design needs, in mm and degrees."""
    return {
        "contact_ratio": pair.contact_ratio,
        "base_pitch_mm": 1e3 * pair.base_pitch_m,
        "path_of_contact_mm": 1e3 * (pair.contact_end_m - pair.contact_start_m),
        "double_contact_length_mm": 1e3 * pair.double_contact_fraction * pair.base_pitch_m,
        "working_pressure_angle_deg": math.degrees(pair.working_pressure_angle_rad),
        "center_distance_mm": 1e3 * pair.center_distance_m,
        "tip_diameter_pinion_mm": 2e3 * pair.tip_radius_pinion_m,
        "tip_diameter_gear_mm": 2e3 * pair.tip_radius_gear_m,
    }


def static_te_record(table, contacts, config) -> dict:
    """``static_te.json``: the first torque's summary at the top level, every torque's in ``torques``."""
    records = [torque_record(table, i, contact) for i, contact in enumerate(contacts)]
    return {
        **records[0],
        "torques": records,
        "stiffness_model": config.mesh.stiffness_model,
        "phases": int(table.phase.size),
        "geometry": geometry_record(contacts[0].geometry),
        "config": config.to_dict(),
    }


def _title(config, pair) -> str:
    profile = config.profile
    reliefs = []
    for key in profile.relieved:
        name = key.removesuffix("_um")
        amount, length = getattr(profile, f"{name}_m"), getattr(profile, f"{name}_length_m")
        reliefs.append(f"{name.removesuffix('_relief').replace('_', ' ')} {1e6 * amount:.3g} um / {1e3 * length:.3g} mm")
    relief = f"{profile.shape} relief: " + ", ".join(reliefs) if reliefs else "no relief"
    return f"{config.mesh.stiffness_model}, contact ratio {pair.contact_ratio:.3f}; {relief}"


def run(config, args, out_dir) -> int:
    from ..gear.contact import loaded_te_table
    from ..outputs.io import save_figure_atomic, write_csv_atomic, write_json_atomic
    from ..outputs.plots import harris_figure, static_te_figure

    torques = torques_of(config, args)
    contacts = contacts_of(config, torques)
    pair, mesh = contacts[0].geometry, config.mesh
    table = loaded_te_table(pair, [c.pair_stiffness for c in contacts], torques, modification=contacts[0].modification,
                            ste_amplitude_m=mesh.ste_amplitude_m, ste_phase_rad=mesh.ste_phase_rad)
    title = _title(config, pair)
    write_csv_atomic(out_dir / "static_te.csv", static_te_header(table.in_contact.shape[0]), static_te_rows(table))
    write_json_atomic(out_dir / "static_te.json", static_te_record(table, contacts, config))
    save_figure_atomic(static_te_figure(table, title), out_dir / "static_te.png", dpi=120)
    p2p_um = 1e6 * table.p2p_m
    if len(torques) > 1:
        write_csv_atomic(out_dir / "harris.csv", HARRIS_HEADER, zip(table.torque_pinion_Nm, p2p_um))
        save_figure_atomic(harris_figure(table.torque_pinion_Nm, p2p_um, config.load.torque_pinion_Nm, title),
                           out_dir / "harris.png", dpi=120)
    shown = ", ".join(f"{t:g} N m: {p:.4g} um" for t, p in zip(torques, p2p_um))
    print(f"loaded static TE p2p {shown} -> {out_dir}")
    return 0


register(Command("static-te", "loaded static transmission error and the Harris map", add_arguments, run, validate,
                 dynamic_model=False))
