"""What several commands share: the speed option, solving per the config, the solution record.

Light at import (no JAX): the library is imported inside the functions that compute.
"""

from __future__ import annotations

import argparse
import math

from . import positive_float

__all__ = ["add_speed_argument", "solve_config", "solution_record"]


def add_speed_argument(parser: argparse.ArgumentParser, *, many: bool = False) -> None:
    """``--speed RPM`` (one, or several with `many`: ``--speed 3000 5000`` and
    ``--speed 3000 --speed 5000`` both give two speeds)."""
    speed = positive_float("--speed", "a positive pinion speed in rpm")
    if many:
        parser.add_argument("--speed", type=speed, nargs="+", action="extend", default=None, metavar="RPM",
                            help="pinion speed [rpm] (one or more; repeated flags add speeds)")
    else:
        parser.add_argument("--speed", type=speed, required=True, metavar="RPM", help="pinion speed [rpm]")


def solve_config(config, model, speed_rpm: float, z0=None, stability: bool = True):
    """One HB solution with the config's ``[solver]`` settings (``harmonics = "auto"`` honoured),
    with its Floquet multipliers (:func:`hbgear.solve`)."""
    from ..api import solve

    so = config.solver
    return solve(model, speed_rpm=float(speed_rpm), harmonics=so.harmonics if so.harmonics is not None else "auto",
                 nu=so.subharmonic, samples=so.time_samples, tolerance=so.tolerance, max_iterations=so.max_iterations,
                 z0=z0, stability=stability)


def solution_record(solution) -> dict:
    """Speed, read-outs and solver facts of a gear solution, for JSON outputs."""
    wm = float(solution.model.speeds(solution.omega_pinion)[2])
    record = {
        "speed_rpm": solution.speed_rpm,
        "mesh_freq_hz": wm / (2 * math.pi),
        **solution.summary(),
        "harmonics": solution.harmonics,
        "nu": solution.nu,
        "time_samples": solution.samples,
        "residual": solution.residual_norm,
        "newton_iterations": solution.iterations,
        "output_torque_Nm": solution.reaction_force_N * float(solution.model.base_radius_gear_m)
        if solution.model.boundary == "reaction" else None,
    }
    if solution.multipliers is not None:
        from ..engine.floquet import TRIVIAL_TOL, split_neutral, stable_verdict

        m, system, p = solution.multipliers, solution.system, solution.parameter
        record["stable"] = stable_verdict(system, p, m, solution.nu)  # the criterion frc uses
        record["floquet_multipliers"] = [[float(x.real), float(x.imag)] for x in m]
        # the spring boundary's neutral soft mode, left out of "stable" (hbgear.gear.soft_mode)
        neutral = split_neutral(m, system.neutral_multipliers(p, solution.nu), TRIVIAL_TOL)[1]
        record["neutral_soft_mode_multipliers"] = [[float(x.real), float(x.imag)] for x in neutral]
    return record
