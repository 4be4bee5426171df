"""``hbgear validate CONFIG [--speed RPM ...] [--tolerance REL]``: harmonic balance against time integration.

At each speed the same model is solved by harmonic balance and integrated in time to steady
state; ``validation.csv`` lists both RMS and peak-to-peak DTE and their relative differences,
``validation.png`` overlays the DTE waveforms over one period and their spectra.

A gate: when ``|HB / TI - 1|`` of the DTE RMS or peak-to-peak exceeds ``--tolerance`` (default
1e-3) at any speed, the outputs are still written and the command exits with status 3, one
stderr line naming each speed and quantity that disagree (:class:`hbgear.cli.CheckFailed`).
"""

from __future__ import annotations

import numpy as np

from . import CheckFailed, Command, positive_float, register
from ..outputs.io import save_figure_atomic, write_csv_atomic
from ..gear.simulate import simulate
from ..gear.solve import rpm_to_rad_s
from .common import add_speed_argument, model_of, solve_config

HEADER = ["speed_rpm", "hb_dte_rms_um", "ti_dte_rms_um", "hb_dte_p2p_um", "ti_dte_p2p_um", "rel_diff_rms", "rel_diff_p2p"]

#: Default of ``--tolerance``: relative difference allowed between HB and TI (DTE RMS and p2p).
DEFAULT_TOLERANCE = 1e-3


def _speeds(config, args):
    if args.speed:
        return list(args.speed)
    sweep = config.sweep
    return list(np.linspace(sweep.speed_rpm_start, sweep.speed_rpm_stop, 3))


def compare(config, model, speed_rpm: float):
    """``(row, hb_solution, time_response)`` at one speed."""
    solution = solve_config(config, model, speed_rpm)
    sim = config.simulate
    response = simulate(
        model,
        rpm_to_rad_s(speed_rpm),
        max_cycles=sim.cycles,
        rtol=sim.rtol,
        steady_tolerance=sim.steady_tolerance,
    )
    hb, ti = solution.summary(), response.summary
    row = [
        speed_rpm,
        hb["dte_rms_um"],
        ti["dte_rms_um"],
        hb["dte_p2p_um"],
        ti["dte_p2p_um"],
        hb["dte_rms_um"] / ti["dte_rms_um"] - 1.0,
        hb["dte_p2p_um"] / ti["dte_p2p_um"] - 1.0,
    ]
    return row, solution, response


def _plot(results, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(results), 2, figsize=(11, 2.8 * len(results)), squeeze=False)
    for (row, solution, response), (ax_t, ax_f) in zip(results, axes):
        cycles = response.period_cycles
        keep = response.t >= response.t[-1] - cycles * response.mesh_period_s + 1e-15 * response.t[-1]
        t_ti = (response.t[keep] - response.t[keep][0]) / response.mesh_period_s
        ax_t.plot(t_ti, 1e6 * response.q[0][keep], "k-", lw=2.5, alpha=0.35, label="time integration")
        phase0 = response.s[keep][0]
        frac = np.mod(t_ti + phase0, solution.nu) / solution.nu
        q, _ = solution.state_at(frac)
        ax_t.plot(t_ti, 1e6 * q[0], "C3--", lw=1.2, label=f"HB (H={solution.harmonics}, nu={solution.nu})")
        ax_t.set_xlabel("time / mesh period")
        ax_t.set_ylabel("DTE [um]")
        ax_t.set_title(f"{row[0]:g} rpm: rms diff {100 * row[5]:+.3f} %, p2p diff {100 * row[6]:+.3f} %", fontsize=9)
        ax_t.legend(fontsize=7)
        orders = np.array([r[0] for r in solution.harmonic_table()[1:]])
        amps = np.array([r[1] for r in solution.harmonic_table()[1:]])
        n = int(np.sum(keep))
        spec = 1e6 * np.abs(np.fft.rfft(response.q[0][keep][: n - (n % 2)])) * 2 / (n - (n % 2))
        ti_orders = np.arange(spec.size) / cycles
        ax_f.semilogy(ti_orders[1:], spec[1:], "k.", alpha=0.4, label="time integration")
        ax_f.semilogy(orders, amps, "C3x", ms=4, label="HB")
        ax_f.set_xlim(0, min(orders.max(), 40) + 0.5)
        ax_f.set_ylim(max(1e-6, amps.max() * 1e-6), amps.max() * 3)
        ax_f.set_xlabel("mesh order")
        ax_f.set_ylabel("DTE amplitude [um]")
        ax_f.legend(fontsize=7)
    fig.tight_layout()
    save_figure_atomic(fig, path, dpi=110)
    plt.close(fig)


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
    model = model_of(config)
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
