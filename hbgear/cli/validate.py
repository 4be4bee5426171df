"""``hbgear validate CONFIG [--speed RPM ...]``: harmonic balance against time integration.

At each speed the same model is solved by harmonic balance and integrated in time to steady
state; ``validation.csv`` lists both RMS and peak-to-peak DTE and their relative differences,
``validation.png`` overlays the DTE waveforms over one period and their spectra.
"""

from __future__ import annotations

from . import Command, register
from .common import add_speed_argument, solve_config

HEADER = ["speed_rpm", "hb_dte_rms_um", "ti_dte_rms_um", "hb_dte_p2p_um", "ti_dte_p2p_um", "rel_diff_rms", "rel_diff_p2p"]


def _speeds(config, args):
    if args.speed:
        return list(args.speed)
    import numpy as np

    sweep = config.sweep
    return list(np.linspace(sweep.speed_rpm_start, sweep.speed_rpm_stop, 3))


def compare(config, model, speed_rpm: float):
    """``(row, hb_solution, time_response)`` at one speed."""
    from ..api import simulate

    solution = solve_config(config, model, speed_rpm, stability=False)
    sim = config.simulate
    response = simulate(model, speed_rpm=speed_rpm, cycles=sim.cycles, rtol=sim.rtol,
                        steady_tolerance=sim.steady_tolerance)
    hb, ti = solution.summary(), response.summary
    row = [speed_rpm, hb["dte_rms_um"], ti["dte_rms_um"], hb["dte_p2p_um"], ti["dte_p2p_um"],
           hb["dte_rms_um"] / ti["dte_rms_um"] - 1.0, hb["dte_p2p_um"] / ti["dte_p2p_um"] - 1.0]
    return row, solution, response


def run(config, args, out_dir) -> int:
    from ..build import build_model
    from ..outputs.io import save_figure_atomic, write_csv_atomic
    from ..outputs.plots import validation_figure

    model = build_model(config)
    results = []
    for speed in _speeds(config, args):
        results.append(compare(config, model, speed))
        row = results[-1][0]
        print(f"{speed:g} rpm: DTE rms HB {row[1]:.5g} / TI {row[2]:.5g} um ({100 * row[5]:+.3f} %), "
              f"p2p HB {row[3]:.5g} / TI {row[4]:.5g} um ({100 * row[6]:+.3f} %)")
    write_csv_atomic(out_dir / "validation.csv", HEADER, [r[0] for r in results])
    save_figure_atomic(validation_figure(results), out_dir / "validation.png", dpi=110)
    return 0


register(Command("validate", "harmonic balance against time integration at each speed",
                 lambda p: add_speed_argument(p, many=True), run))
