"""What several commands share: the speed option, model building, solving per the config."""

from __future__ import annotations

import argparse

from ..build import build_model
from . import positive_float
from ..gear.solve import PeriodicSolution, auto_harmonics, rpm_to_rad_s, solve_periodic

__all__ = ["add_speed_argument", "model_of", "solve_config", "solution_record"]


def add_speed_argument(parser: argparse.ArgumentParser, *, many: bool = False) -> None:
    """``--speed RPM`` (one, or several with `many`)."""
    parser.add_argument(
        "--speed",
        type=positive_float("--speed", "a positive pinion speed in rpm"),
        required=not many,
        nargs="+" if many else None,
        metavar="RPM",
        help="pinion speed [rpm]" + (" (one or more)" if many else ""),
    )


def model_of(config):
    """The gear-pair model of a config (physics checks raise ConfigError, exit 2)."""
    return build_model(config)


def solve_config(config, model, speed_rpm: float, z0=None) -> PeriodicSolution:
    """One HB solution with the config's solver settings (``harmonics = "auto"`` honoured)."""
    solver = config.solver
    omega = rpm_to_rad_s(speed_rpm)
    if solver.harmonics is None:
        return auto_harmonics(
            model, omega, nu=solver.subharmonic, tolerance=solver.tolerance, max_iterations=solver.max_iterations
        )
    return solve_periodic(
        model,
        omega,
        harmonics=solver.harmonics,
        nu=solver.subharmonic,
        samples=solver.time_samples,
        tolerance=solver.tolerance,
        max_iterations=solver.max_iterations,
        z0=z0,
    )


def solution_record(solution: PeriodicSolution) -> dict:
    """Speed, read-outs and solver facts of a solution, for JSON outputs."""
    wm = float(solution.model.speeds(solution.omega_pinion)[2])
    return {
        "speed_rpm": solution.speed_rpm,
        "mesh_freq_hz": wm / (2 * 3.141592653589793),
        **solution.summary(),
        "harmonics": solution.harmonics,
        "nu": solution.nu,
        "time_samples": solution.samples,
        "residual": solution.residual_norm,
        "newton_iterations": solution.iterations,
        "output_torque_Nm": solution.reaction_force_N * float(solution.model.base_radius_gear_m)
        if solution.model.boundary == "reaction"
        else None,
    }


def floquet_of(solution: PeriodicSolution):
    """Floquet multipliers of a solution (trivial ones removed): Hill's method, or the variational
    equations at many harmonics (:func:`~hbgear.gear.monodromy.solution_multipliers`)."""
    from ..gear.monodromy import solution_multipliers

    return solution_multipliers(solution)
