"""``hbgear validate CONFIG [--speed RPM ...] [--tolerance REL]``: harmonic balance against time integration.

At each speed the same model is solved by harmonic balance and integrated in time to steady
state; ``validation.csv`` lists both RMS and peak-to-peak DTE and their relative differences,
``validation.png`` overlays the DTE waveforms over one period and their spectra.

A gate: when ``|HB / TI - 1|`` of the DTE RMS or peak-to-peak exceeds ``--tolerance`` (default
1e-3) at any speed, the outputs are still written and the command exits with status 3, one
stderr line naming each speed and quantity that disagree (:class:`hbgear.cli.CheckFailed`).
"""

from __future__ import annotations

from . import CheckFailed, Command, positive_float, register
from .common import add_speed_argument, solve_config

HEADER = ["speed_rpm", "hb_dte_rms_um", "ti_dte_rms_um", "hb_dte_p2p_um", "ti_dte_p2p_um", "rel_diff_rms", "rel_diff_p2p"]

#: Default of ``--tolerance``: relative difference allowed between HB and TI (DTE RMS and p2p).
DEFAULT_TOLERANCE = 1e-3


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


def _plot(results, path) -> None:
    """``validation.png`` (:func:`hbgear.outputs.plots.validation_figure`), written atomically."""
    from ..outputs.io import save_figure_atomic
    from ..outputs.plots import validation_figure

    save_figure_atomic(validation_figure(results), path, dpi=110)


def disagreements(rows, tolerance: float) -> list[str]:
    """``"<speed> rpm DTE <quantity> <diff> %"`` for every row whose ``|rel_diff_rms|`` or
    ``|rel_diff_p2p|`` exceeds `tolerance` (or is not finite)."""
    found = []
    for row in rows:
        for name, diff in (("RMS", row[5]), ("p2p", row[6])):
            if not abs(diff) <= tolerance:  # NaN disagrees too
                found.append(f"{row[0]:g} rpm DTE {name} HB vs TI {100 * diff:+.4g} %")
    return found


def add_arguments(parser) -> None:
    add_speed_argument(parser, many=True)
    parser.add_argument(
        "--tolerance",
        type=positive_float("--tolerance", "a positive relative difference, e.g. 1e-3"),
        default=DEFAULT_TOLERANCE,
        metavar="REL",
        help=f"largest |HB/TI - 1| of the DTE RMS and peak-to-peak accepted (default {DEFAULT_TOLERANCE:g}); "
        "beyond it the command exits with status 3 after writing its outputs",
    )


def run(config, args, out_dir) -> int:
    from ..build import build_model
    from ..outputs.io import write_csv_atomic

    model = build_model(config)
    results = []
    for speed in _speeds(config, args):
        results.append(compare(config, model, speed))
        row = results[-1][0]
        print(f"{speed:g} rpm: DTE rms HB {row[1]:.5g} / TI {row[2]:.5g} um ({100 * row[5]:+.3f} %), "
              f"p2p HB {row[3]:.5g} / TI {row[4]:.5g} um ({100 * row[6]:+.3f} %)")
    rows = [r[0] for r in results]
    write_csv_atomic(out_dir / "validation.csv", HEADER, rows)
    _plot(results, out_dir / "validation.png")
    failed = disagreements(rows, args.tolerance)
    if failed:
        raise CheckFailed(f"{'; '.join(failed)} (tolerance {100 * args.tolerance:g} %; outputs written to {out_dir})")
    return 0


register(Command("validate", "harmonic balance against time integration at each speed", add_arguments, run))
