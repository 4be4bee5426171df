"""The figures hbgear writes; the only module that imports matplotlib (inside each function).

Each function takes a result object (or arrays) and returns a ``matplotlib.figure.Figure`` built
without pyplot's global state (so it is safe in any backend and never pops up a window); save it
with :func:`hbgear.outputs.io.save_figure_atomic`.
"""

from __future__ import annotations

import numpy as np

__all__ = ["frc_figure", "system_curve_figure", "timeseries_figure", "validation_figure", "stability_map_figure",
           "study_figure", "CONTOUR_MARGIN"]

#: The unit contour of a stability map is drawn at 1 + this, so a neutral mode (the soft output
#: spring's, whose modulus is 1 to within rounding) does not draw noise all over the map.
CONTOUR_MARGIN = 1e-6


def _figure(**kwargs):
    from matplotlib.figure import Figure

    return Figure(**kwargs)


def _mesh_frequency_axis(ax, teeth_pinion: float) -> None:
    """A top x-axis in mesh frequency [Hz] beside the pinion speed [rpm] (``f_m = Z_p n / 60``)."""
    top = ax.secondary_xaxis("top", functions=(lambda rpm: rpm * teeth_pinion / 60.0,
                                               lambda hz: hz * 60.0 / teeth_pinion))
    top.set_xlabel("mesh frequency [Hz]", fontsize=8)
    top.tick_params(labelsize=8)


def frc_figure(curve, title: str | None = None):
    """DTE RMS and peak-to-peak against speed for a gear frequency-response curve
    (:class:`hbgear.api.FrequencyResponse`): the ``nu`` branch in black, unstable points red,
    folds, ``nu = 2`` branches green, period doublings as squares, the exact scan's unstable zones
    shaded; a mesh-frequency axis on top."""
    model = curve.model
    n = curve.points
    speed, stable = curve.speed_rpm, curve.stable
    folds = curve.response.branch.folds
    records = [r for r in curve.period_doublings if "speed_rpm" in r]
    if title is None:
        b = curve.response.branch
        title = (f"{model.coupling} {model.formulation}, {model.boundary}, H={curve.harmonics}, "
                 f"nu={curve.response.hb.nu}: {n} points, {len(folds)} folds"
                 + ("" if curve.success else f" [{b.status.name}]")
                 + (f", {len(curve.response.doubled)} nu=2 branch(es)" if curve.response.doubled else ""))
    fig = _figure(figsize=(8, 6.5))
    axes = fig.subplots(2, 1, sharex=True)
    for ax, values, label in ((axes[0], curve.dte_rms_um, "DTE RMS [um]"), (axes[1], curve.dte_p2p_um,
                                                                          "DTE peak-to-peak [um]")):
        main, st = values[:n], stable[:n]
        ax.plot(speed[:n], main, color="k", lw=1.0, label="HB continuation (nu = 1)")
        for k, zone in enumerate(curve.unstable_zones):
            ax.axvspan(zone["speed_rpm_from"], zone["speed_rpm_to"], color="tab:red", alpha=0.15, lw=0,
                       label="unstable zone (exact scan)" if k == 0 else None)
        if np.any(st == 0):
            ax.plot(speed[:n][st == 0], main[st == 0], "o", ms=3, color="tab:red", label="unstable")
        if len(folds):
            ax.plot(speed[folds], values[folds], "D", ms=6, mfc="none", color="tab:blue", label="fold")
        first = n
        for k, d in enumerate(curve.response.doubled):
            rows = slice(first, first + len(d.p))
            first += len(d.p)
            ax.plot(speed[rows], values[rows], color="tab:green", lw=1.2,
                    label="period-doubled branch (nu = 2)" if k == 0 else None)
            bad = stable[rows] == 0
            if np.any(bad):
                ax.plot(speed[rows][bad], values[rows][bad], "x", ms=4, color="tab:red",
                        label="unstable (nu = 2)" if k == 0 else None)
        if records:
            at = [int(np.argmin(np.abs(speed[:n] - r["speed_rpm"]))) for r in records]
            ax.plot([r["speed_rpm"] for r in records], main[at], "s", ms=6, mfc="none", color="tab:purple",
                    label="period doubling")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    _mesh_frequency_axis(axes[0], float(model.teeth_pinion))
    axes[0].legend(fontsize=8, loc="upper left")
    axes[1].set_xlabel("pinion speed [rpm]")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return fig


def system_curve_figure(curve, coordinate: int = 0, title: str | None = None):
    """``max |q_i(t)|`` against the parameter for any system's curve, unstable points red, folds marked."""
    fig = _figure(figsize=(7, 4))
    ax = fig.subplots()
    p, amp, stable = curve.parameter, curve.max_abs(coordinate), curve.stable
    ax.plot(p, amp, color="k", lw=1.0, label="HB continuation")
    if np.any(stable == 0):
        ax.plot(p[stable == 0], amp[stable == 0], "o", ms=3, color="tab:red", label="unstable")
    folds = curve.branch.folds
    if len(folds):
        ax.plot(p[folds], amp[folds], "D", ms=6, mfc="none", color="tab:blue", label="fold")
    ax.set_xlabel("parameter")
    ax.set_ylabel(f"max |q_{coordinate}(t)|")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title(title or f"{type(curve.system).__name__}: {len(curve)} points, {len(folds)} folds", fontsize=10)
    fig.tight_layout()
    return fig


def timeseries_figure(record, pair_slots: int, title: str | None = None):
    """DTE; mesh force and per-pair normal loads; per-pair friction forces of a time record
    (fields ``t, s, q, mesh_force, pairs``; e.g. a :class:`~hbgear.gear.simulate.TimeResponse`)."""
    t_ms = 1e3 * np.asarray(record.t)
    fig = _figure(figsize=(8, 8))
    axes = fig.subplots(3, 1, sharex=True)
    axes[0].plot(t_ms, 1e6 * record.q[0], color="k")
    axes[0].set_ylabel("DTE [um]")
    axes[1].plot(t_ms, record.mesh_force, color="k", label="mesh force")
    contact = record.pairs["sigma"] > 0
    for k in range(pair_slots):
        axes[1].plot(t_ms, np.where(contact[k], record.pairs["normal"][k], np.nan), label=f"pair {k + 1} normal load")
        axes[2].plot(t_ms, np.where(contact[k], record.pairs["friction"][k], np.nan), label=f"pair {k + 1}")
    axes[1].set_ylabel("force [N]")
    axes[2].set_ylabel("friction force [N]")
    axes[2].set_xlabel("time [ms]")
    for ax in axes[1:]:
        ax.legend(fontsize=8, loc="upper right")
    for ax in axes:
        ax.grid(alpha=0.3)
    if title is None:
        title = (f"{record.speed_rpm:.6g} rpm: steady state after {record.cycles} mesh cycles "
                 f"(period {record.period_cycles} mesh cycle{'s' if record.period_cycles > 1 else ''})")
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def validation_figure(results):
    """Per speed: the DTE waveform of time integration and of harmonic balance over the steady
    period, and their spectra. `results`: ``(row, solution, time_response)`` triples, ``row`` as in
    ``validation.csv`` (speed, HB/TI RMS and p2p, relative differences)."""
    fig = _figure(figsize=(11, 2.8 * len(results)))
    axes = fig.subplots(len(results), 2, squeeze=False)
    for (row, solution, response), (ax_t, ax_f) in zip(results, axes):
        cycles = response.period_cycles
        keep = response.t >= response.t[-1] - cycles * response.mesh_period_s + 1e-15 * response.t[-1]
        t_ti = (response.t[keep] - response.t[keep][0]) / response.mesh_period_s
        ax_t.plot(t_ti, 1e6 * response.q[0][keep], "k-", lw=2.5, alpha=0.35, label="time integration")
        frac = np.mod(t_ti + response.s[keep][0], solution.nu) / solution.nu
        q, _ = solution.state_at(frac)
        ax_t.plot(t_ti, 1e6 * q[0], "C3--", lw=1.2, label=f"HB (H={solution.harmonics}, nu={solution.nu})")
        ax_t.set_xlabel("time / mesh period")
        ax_t.set_ylabel("DTE [um]")
        ax_t.set_title(f"{row[0]:g} rpm: rms diff {100 * row[5]:+.3f} %, p2p diff {100 * row[6]:+.3f} %", fontsize=9)
        ax_t.legend(fontsize=7)
        table = solution.harmonic_table()[1:]
        orders, amps = np.array([r[0] for r in table]), np.array([r[1] for r in table])
        n = int(np.sum(keep))
        n -= n % 2
        spec = 1e6 * np.abs(np.fft.rfft(response.q[0][keep][:n])) * 2 / n
        ax_f.semilogy((np.arange(spec.size) / cycles)[1:], spec[1:], "k.", alpha=0.4, label="time integration")
        ax_f.semilogy(orders, amps, "C3x", ms=4, label="HB")
        ax_f.set_xlim(0, min(orders.max(), 40) + 0.5)
        ax_f.set_ylim(max(1e-6, amps.max() * 1e-6), amps.max() * 3)
        ax_f.set_xlabel("mesh order")
        ax_f.set_ylabel("DTE amplitude [um]")
        ax_f.legend(fontsize=7)
    fig.tight_layout()
    return fig


def _positions(values) -> tuple[np.ndarray, list | None]:
    """Numeric x positions of a varied key's values (categorical ones: 0, 1, ... and their labels)."""
    values = np.asarray(values, dtype=object)
    try:
        return values.astype(float), None
    except (TypeError, ValueError):
        labels = list(dict.fromkeys(str(v) for v in values))
        return np.array([labels.index(str(v)) for v in values], dtype=float), labels


def study_figure(kind: str, values: dict, metrics: dict, success, title: str = ""):
    """A study's picture. `values` ``{varied key: per-sample values}``, `metrics` ``{name:
    per-sample values}`` (the first is the main one), `success` per sample (failed samples are
    left out). Grid: each metric against the first varied key, one line per combination of the
    other keys' values. Monte Carlo: the main metric against each varied key (scatter) and its
    histogram."""
    success = np.asarray(success, dtype=bool)
    keys, names = list(values), list(metrics)
    if kind == "grid":
        fig = _figure(figsize=(4.4 * len(names), 3.6), layout="constrained")
        axes = np.atleast_1d(fig.subplots(1, len(names)))
        x, labels = _positions(values[keys[0]])
        others = [tuple(str(values[k][i]) for k in keys[1:]) for i in range(len(x))]
        for ax, name in zip(axes, names):
            y = np.asarray(metrics[name], dtype=float)
            for group in dict.fromkeys(others):
                rows = [i for i in range(len(x)) if others[i] == group and success[i]]
                rows.sort(key=lambda i: x[i])
                label = ", ".join(f"{k} = {v}" for k, v in zip(keys[1:], group)) or None
                ax.plot(x[rows], y[rows], "o-", ms=4, label=label)
            ax.set_xlabel(keys[0])
            ax.set_ylabel(name)
            if labels is not None:
                ax.set_xticks(range(len(labels)), labels, fontsize=7)
            if len(keys) > 1 and ax is axes[0]:
                ax.legend(fontsize=7)
            ax.grid(alpha=0.3)
    else:
        shown = keys[:3]
        fig = _figure(figsize=(3.4 * (len(shown) + 1), 3.2), layout="constrained")
        axes = np.atleast_1d(fig.subplots(1, len(shown) + 1))
        y = np.asarray(metrics[names[0]], dtype=float)
        for ax, key in zip(axes, shown):
            x, labels = _positions(values[key])
            ax.plot(x[success], y[success], ".", ms=5, alpha=0.7)
            ax.set_xlabel(key)
            ax.set_ylabel(names[0])
            if labels is not None:
                ax.set_xticks(range(len(labels)), labels, fontsize=7)
            ax.grid(alpha=0.3)
        ok = y[success & np.isfinite(y)]
        axes[-1].hist(ok, bins=max(5, min(30, int(np.sqrt(max(len(ok), 1))) * 2)), color="0.45")
        axes[-1].set_xlabel(names[0])
        axes[-1].set_ylabel("samples")
    fig.suptitle(title, fontsize=9)
    return fig


def stability_map_figure(speeds_rpm, contact_ratios, values, title: str = "", ax=None):
    """Colour map of ``max |multiplier|`` over speed x contact ratio with the unit contour (a line
    plot per contact ratio when the grid has one row or column); drawn on `ax` when given."""
    from matplotlib.colors import TwoSlopeNorm

    speeds_rpm, contact_ratios = np.asarray(speeds_rpm), np.asarray(contact_ratios)
    values = np.asarray(values, dtype=float)
    if ax is None:
        fig = _figure(figsize=(7.5, 4.8), layout="constrained")
        ax = fig.subplots()
    else:
        fig = ax.figure
    finite = values[np.isfinite(values)]
    lo = float(finite.min()) if finite.size else 0.5
    hi = float(finite.max()) if finite.size else 1.5
    lo, hi = min(lo, 1.0 - 1e-3), max(hi, 1.0 + 1e-3)
    if len(speeds_rpm) > 1 and len(contact_ratios) > 1:
        mesh = ax.pcolormesh(speeds_rpm, contact_ratios, values, shading="nearest", cmap="RdBu_r",
                             norm=TwoSlopeNorm(1.0, lo, hi))
        fig.colorbar(mesh, ax=ax, label="max |multiplier|")
        if np.nanmin(values) < 1.0 + CONTOUR_MARGIN < np.nanmax(values):
            ax.contour(speeds_rpm, contact_ratios, values, levels=[1.0 + CONTOUR_MARGIN], colors="k", linewidths=1.2)
        ax.set_ylabel("contact ratio Gamma [-]")
    else:
        for i, g in enumerate(contact_ratios):
            ax.plot(speeds_rpm, values[i], ".-", label=f"Gamma = {g:.4g}")
        ax.axhline(1.0, color="k", lw=0.8)
        ax.set_ylabel("max |multiplier|")
        ax.legend(fontsize=8)
    ax.set_xlabel("pinion speed [rpm]")
    ax.set_title(title, fontsize=8)
    return fig
