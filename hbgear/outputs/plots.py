"""The figures hbgear writes; the only module that imports matplotlib (inside each function).

Each function takes a result object (or arrays) and returns a ``matplotlib.figure.Figure`` built
without pyplot's global state (so it is safe in any backend and never pops up a window); save it
with :func:`hbgear.outputs.io.save_figure_atomic`.
"""

from __future__ import annotations

import numpy as np

__all__ = ["frc_figure", "orders_figure", "dynamic_factor_figure", "floquet_figure", "system_curve_figure",
           "bearing_forces_figure", "campbell_figure",
           "timeseries_figure", "validation_figure", "stability_map_figure", "static_te_figure", "harris_figure",
           "study_figure", "CONTOUR_MARGIN", "ORDER_MAP_RANGE_DB"]

#: The unit contour of a stability map is drawn at 1 + this, so a neutral mode (the soft output
#: spring's, whose modulus is 1 to within rounding) does not draw noise all over the map.
CONTOUR_MARGIN = 1e-6

#: The colour scale of the order map spans this many dB below its largest amplitude.
ORDER_MAP_RANGE_DB = 60.0


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


def _plain_log_ticks(axis) -> None:
    """Decade labels as plain numbers (``0.01``, ``100``) and unlabelled minor ticks at 2 and 5
    on a log axis: no mathtext to typeset, which is most of a log axis's drawing time."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    axis.set_major_formatter(FuncFormatter(lambda value, _: f"{value:g}"))
    axis.set_minor_locator(LogLocator(subs=(2.0, 5.0)))
    axis.set_minor_formatter(NullFormatter())


def _branch_rows(curve):
    """``(rows, nu)`` slices of the table: the ``nu`` branch, then each ``nu = 2`` branch."""
    first, parts = curve.points, [(slice(0, curve.points), int(curve.response.hb.nu))]
    for d in curve.response.doubled:
        parts.append((slice(first, first + len(d.p)), 2))
        first += len(d.p)
    return parts


def _order_map(speed, values_db, parts, bins: int):
    """``(edges, grid)``: `values_db` ``(rows, orders)`` on a uniform speed grid of `bins` cells.
    Per branch (`parts`, row slices) a cell takes the largest value of the branch's points in it
    (a fold's two sides meet in one cell) or, between the branch's points, the value interpolated
    over them sorted by speed; the grid is the largest over the branches (-inf where none is)."""
    edges = np.linspace(speed.min(), speed.max(), bins + 1)
    centres = 0.5 * (edges[1:] + edges[:-1])
    grid = np.full((bins, values_db.shape[1]), -np.inf)
    for rows in parts:
        v, s = values_db[rows], speed[rows]
        if not len(s):
            continue
        own = np.full_like(grid, -np.inf)
        np.maximum.at(own, np.clip(np.searchsorted(edges, s, side="right") - 1, 0, bins - 1), v)
        gap = ~np.isfinite(own[:, 0]) & (centres >= s.min()) & (centres <= s.max())
        order = np.argsort(s, kind="stable")
        for k in range(v.shape[1]):
            own[gap, k] = np.interp(centres[gap], s[order], v[order, k])
        grid = np.maximum(grid, own)
    return edges, grid


def orders_figure(curve, orders, amplitudes_um, resonance=None, title: str | None = None):
    """Order tracking of a gear frequency-response curve: the DTE amplitude at each mesh order
    against speed (log scale; integer orders solid, half orders of ``nu = 2`` rows dashed), and the
    colour map speed x order in dB re 1 um (per speed cell the largest amplitude of the solutions
    there: both sides of a fold, a ``nu = 2`` branch beside the ``nu = 1`` one), the way order
    tracking shows measured gearbox data. With `resonance` (ISO 6336-1 numbers) the
    map carries the curve ``order = n_E1 / n`` where an order's frequency is the mesh mode's.

    **Arguments:** `curve` (:class:`hbgear.api.FrequencyResponse`), `orders` (mesh orders),
    `amplitudes_um` ``(rows, orders)`` (:meth:`~hbgear.gear.response.GearFrequencyResponse.order_amplitudes_um`).
    """
    from matplotlib import colormaps
    from matplotlib.lines import Line2D

    orders, amp = np.asarray(orders, dtype=float), np.asarray(amplitudes_um, dtype=float)
    speed, n = curve.speed_rpm, curve.points
    whole = orders == np.round(orders)
    fig = _figure(figsize=(9, 7.5))
    lines_ax, map_ax = fig.subplots(2, 1, sharex=True)
    fig.subplots_adjust(left=0.09, right=0.8, bottom=0.07, top=0.88, hspace=0.08)
    colours = colormaps["viridis"](np.linspace(0.0, 0.9, int(np.ceil(orders.max()))))
    for rows, nu in _branch_rows(curve):
        for k, order in enumerate(orders):
            if (not whole[k] and nu == 1) or (nu == 2 and rows.start >= n and whole[k]):
                continue  # no half orders on nu = 1 rows; of a nu = 2 branch only its half orders
            values = np.where(amp[rows, k] > 0, amp[rows, k], np.nan)
            lines_ax.semilogy(speed[rows], values, color=colours[int(np.ceil(order)) - 1], lw=1.0 if whole[k] else 0.8,
                              ls="-" if whole[k] else "--")
    handles = [Line2D([], [], color=colours[int(o) - 1], lw=1.2, label=f"order {o:g}") for o in orders[whole]]
    if not np.all(whole):
        handles.append(Line2D([], [], color="0.3", ls="--", lw=0.8, label="half orders (nu = 2)"))
    lines_ax.legend(handles=handles, fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    lines_ax.set_ylabel("DTE amplitude [um]")
    _plain_log_ticks(lines_ax.yaxis)
    lines_ax.grid(alpha=0.3)

    shown = np.argsort(orders, kind="stable")
    with np.errstate(divide="ignore"):
        db = 20.0 * np.log10(amp[:, shown])  # re 1 um
    top = float(np.max(db[np.isfinite(db)])) if np.any(np.isfinite(db)) else 0.0
    floor = top - ORDER_MAP_RANGE_DB
    parts = [rows for rows, _ in _branch_rows(curve)]
    edges, grid = _order_map(speed, np.maximum(db, floor), parts, min(600, max(len(speed), 2)))
    values = orders[shown]
    steps = np.diff(values).min() if len(values) > 1 else 1.0
    order_edges = np.concatenate([values - 0.5 * steps, [values[-1] + 0.5 * steps]])
    mesh = map_ax.pcolormesh(edges, order_edges, np.maximum(grid, floor).T, cmap="magma", vmin=floor, vmax=top,
                             shading="flat", rasterized=True)
    box = map_ax.get_position()
    fig.colorbar(mesh, cax=fig.add_axes((box.x1 + 0.015, box.y0, 0.02, box.height)),
                 label="DTE amplitude [dB re 1 um]")
    n_grid = np.linspace(edges[0], edges[-1], 400)
    if resonance is not None and np.any((resonance.n_E1_rpm / n_grid >= order_edges[0])
                                        & (resonance.n_E1_rpm / n_grid <= order_edges[-1])):
        map_ax.plot(n_grid, resonance.n_E1_rpm / n_grid, color="w", ls="--", lw=1.0,
                    label=f"order x mesh frequency = mesh mode (n_E1 / n, n_E1 = {resonance.n_E1_rpm:.0f} rpm)")
        map_ax.legend(fontsize=7, loc="upper right", framealpha=0.6)
    map_ax.set_ylim(order_edges[0], order_edges[-1])
    map_ax.set_ylabel("mesh order")
    map_ax.set_xlabel("pinion speed [rpm]")
    _mesh_frequency_axis(lines_ax, float(curve.model.teeth_pinion))
    model = curve.model
    fig.suptitle(title or f"DTE order tracking: {model.coupling} {model.formulation}, {model.boundary}, "
                 f"H={curve.harmonics}, {len(speed)} rows", fontsize=10)
    return fig


def _resonance_ranges(ax, resonance) -> None:
    """ISO 6336-1 ranges of the resonance ratio on `ax` (pinion speed axis): ``n_E1`` and the main
    resonance range shaded, the intermediate range lighter, the ranges named at the top; legend
    entries only for what lies in the axis' speed range."""
    lo, hi = ax.get_xlim()
    n_e1 = resonance.n_E1_rpm
    seen = lambda a, b: min(b, hi) > max(a, lo)  # noqa: E731
    main, intermediate = resonance.main_resonance_rpm, resonance.intermediate_rpm
    ax.axvspan(*main, color="tab:orange", alpha=0.22, lw=0,
               label=f"main resonance range {resonance.N_S:g} < N <= 1.15" if seen(*main) else None)
    ax.axvspan(*intermediate, color="tab:orange", alpha=0.08, lw=0,
               label="intermediate 1.15 < N < 1.5" if seen(*intermediate) else None)
    ax.axvline(n_e1, color="tab:orange", lw=1.2,
               label=f"n_E1 = {n_e1:.0f} rpm (ISO 6336-1)" if lo <= n_e1 <= hi else None)
    names = (("subcritical ", resonance.subcritical_rpm, "right"), ("main", main, "center"),
             ("interm.", intermediate, "center"), (" supercritical", resonance.supercritical_rpm, "left"))
    for name, (a, b), align in names:
        a, b = max(a, lo), min(b, hi)
        if b > a:
            x = {"right": b, "center": 0.5 * (a + b), "left": a}[align]
            ax.text(x, 0.98, name, transform=ax.get_xaxis_transform(), ha=align, va="top", fontsize=7, color="0.35")
    ax.set_xlim(lo, hi)


def dynamic_factor_figure(curve, resonance, title: str | None = None):
    """The dynamic factor ``max F_mesh / N`` (``N = T_p / R_bp``) of a gear curve against speed, with the ISO 6336-1
    resonance speed ``n_E1``, its main resonance range and the other ranges marked, and the
    resonance ratio ``N = n / n_E1`` on the top axis; unstable points red, ``nu = 2`` branches green."""
    n, speed, factor, stable = curve.points, curve.speed_rpm, curve.dynamic_factor, curve.stable
    fig = _figure(figsize=(8, 4.5))
    ax = fig.subplots()
    fig.subplots_adjust(left=0.08, right=0.98, bottom=0.11, top=0.83)
    for k, (rows, nu) in enumerate(_branch_rows(curve)):
        main = rows.start < n
        ax.plot(speed[rows], factor[rows], color="k" if main else "tab:green", lw=1.0,
                label="HB continuation" if main else ("period-doubled branch (nu = 2)" if k == 1 else None))
    bad = stable[:n] == 0
    if np.any(bad):
        ax.plot(speed[:n][bad], factor[:n][bad], "o", ms=3, color="tab:red", label="unstable")
    ax.axhline(1.0, color="0.5", lw=0.8)
    ax.set_xlim(float(speed.min()), float(speed.max()))
    _resonance_ranges(ax, resonance)
    peak = int(np.argmax(factor[:n]))
    top = ax.secondary_xaxis("top", functions=(lambda rpm: rpm / resonance.n_E1_rpm,
                                               lambda ratio: ratio * resonance.n_E1_rpm))
    top.set_xlabel("resonance ratio N = n / n_E1", fontsize=8)
    top.tick_params(labelsize=8)
    ax.set_xlabel("pinion speed [rpm]")
    ax.set_ylabel("dynamic factor max F_mesh / (T_p / R_bp) [-]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="best")
    fig.suptitle(title or f"dynamic factor: peak {factor[peak]:.3g} at {speed[peak]:.0f} rpm "
                 f"(N = {speed[peak] / resonance.n_E1_rpm:.3f})", fontsize=10)
    return fig


def bearing_forces_figure(curve, title: str | None = None, modes=None):
    """RMS of the dynamic bearing forces ``k y + c y'`` of a gear curve on bearings against speed:
    LOA (solid) and OLOA (dashed), pinion (blue) and gear (orange); the ``nu`` branch only, unstable
    points red. With `modes` (:class:`~hbgear.gear.modes.Modes`) the speeds where mesh order 1 meets
    each natural frequency are marked on the top edge."""
    n, speed = curve.points, curve.speed_rpm[:curve.points]
    fig = _figure(figsize=(8, 4.5))
    ax = fig.subplots()
    fig.subplots_adjust(left=0.09, right=0.98, bottom=0.11, top=0.83)
    for end, colour in (("pinion", "tab:blue"), ("gear", "tab:orange")):
        for direction, style in (("loa", "-"), ("oloa", "--")):
            values = curve.table[f"bearing_force_{end}_{direction}_rms_N"][:n]
            ax.plot(speed, values, style, color=colour, lw=1.1, label=f"{end} {direction.upper()}")
            bad = curve.stable[:n] == 0
            if np.any(bad):
                ax.plot(speed[bad], values[bad], "o", ms=2.5, color="tab:red")
    ax.set_yscale("log")
    ax.set_xlim(float(speed.min()), float(speed.max()))
    if modes is not None:
        for f, name in zip(modes.frequencies_hz, modes.names):
            rpm = 60.0 * f / float(curve.model.teeth_pinion)
            if speed.min() <= rpm <= speed.max():
                ax.axvline(rpm, color="0.6", lw=0.7, ls=":")
                ax.text(rpm, 1.0, name, transform=ax.get_xaxis_transform(), rotation=90, fontsize=6, va="top",
                        ha="right", color="0.35")
    _mesh_frequency_axis(ax, float(curve.model.teeth_pinion))
    ax.set_xlabel("pinion speed [rpm]")
    ax.set_ylabel("bearing force RMS about the mean [N]")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7, loc="best")
    fig.suptitle(title or "dynamic bearing forces along (LOA) and across (OLOA) the line of action", fontsize=10)
    return fig


def campbell_figure(modes, model, speed_rpm_range, orders: int = 10, title: str | None = None):
    """Campbell diagram: mesh orders ``r = 1..orders`` as lines ``f = r Z_p n / 60`` against pinion
    speed, the natural frequencies of the mean-stiffness model (:class:`~hbgear.gear.modes.Modes`)
    as horizontal lines named by their dominant element, and their crossings in the speed range
    marked (where a resonance on the curve is to be expected)."""
    lo, hi = sorted(float(v) for v in speed_rpm_range)
    zp = float(model.teeth_pinion)
    fig = _figure(figsize=(8, 5))
    ax = fig.subplots()
    fig.subplots_adjust(left=0.1, right=0.8, bottom=0.1, top=0.92)
    n = np.linspace(0.0, hi, 2)
    top = orders * zp * hi / 60.0
    shown = [f for f in modes.frequencies_hz if f <= top]
    f_max = 1.1 * max([zp * hi / 60.0 * min(orders, 3)] + shown)
    for r in range(1, orders + 1):
        ax.plot(n, r * zp * n / 60.0, color="0.5", lw=0.8)
        x_end = min(hi, 60.0 * f_max / (r * zp))
        ax.text(x_end, r * zp * x_end / 60.0, f" {r}", fontsize=7, color="0.3", va="bottom")
    label_y = -np.inf
    for f, name in sorted(zip(modes.frequencies_hz, modes.names)):
        if f > f_max:
            continue
        ax.axhline(f, color="tab:blue", lw=1.0)
        label_y = max(f, label_y + 0.035 * f_max)  # labels kept apart, in frequency order
        ax.annotate(f"{name} {f:.0f} Hz", (1.0, f), xycoords=ax.get_yaxis_transform(), xytext=(1.01, label_y),
                    textcoords=ax.get_yaxis_transform(), fontsize=6.5, va="center", color="tab:blue",
                    arrowprops=dict(arrowstyle="-", color="tab:blue", lw=0.5))
        speeds = 60.0 * f / (np.arange(1, orders + 1) * zp)
        inside = (speeds >= lo) & (speeds <= hi)
        ax.plot(speeds[inside], np.full(int(inside.sum()), f), "o", ms=4, color="tab:red")
    ax.axvspan(lo, hi, color="0.93", zorder=0)
    ax.set_xlim(0.0, hi)
    ax.set_ylim(0.0, f_max)
    ax.set_xlabel("pinion speed [rpm]")
    ax.set_ylabel("frequency [Hz]")
    ax.grid(alpha=0.3)
    fig.suptitle(title or "Campbell diagram: mesh orders (grey) and natural frequencies at mean mesh stiffness "
                 "(crossings in the sweep red)", fontsize=9)
    return fig


def floquet_figure(curve, points, title: str | None = None):
    """Floquet multipliers of selected points of a gear curve: in the complex plane with the unit
    circle, and their modulus against their angle (where a multiplier leaves the circle: through
    +1, -1 or as a complex pair), one colour per point, the legend with each point's speed.

    **Arguments:** `curve`; `points`: dicts ``row``, ``speed_rpm``, ``reason``
    (:meth:`~hbgear.gear.response.GearFrequencyResponse.floquet_points`).
    """
    fig = _figure(figsize=(10, 5.8))
    plane, polar = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1.0, 1.25]})
    fig.subplots_adjust(left=0.08, right=0.98, bottom=0.24, top=0.9, wspace=0.25)
    angle = np.linspace(0.0, 2.0 * np.pi, 361)
    plane.plot(np.cos(angle), np.sin(angle), color="0.4", lw=0.8)
    polar.axhline(1.0, color="0.4", lw=0.8)
    markers = "osD^vP"
    for k, point in enumerate(points):
        m = np.asarray(curve.response.multipliers[point["row"]], dtype=complex)
        style = dict(marker=markers[k % len(markers)], ls="none", ms=6, mfc="none", mew=1.3, color=f"C{k}")
        plane.plot(m.real, m.imag, **style)
        polar.plot(np.degrees(np.angle(m)), np.abs(m), **style,
                   label=f"{point['speed_rpm']:.0f} rpm, max |mu| = {point['max_abs_floquet']:.4f}: {point['reason']}")
    plane.set_aspect("equal")
    plane.set_xlabel("Re mu")
    plane.set_ylabel("Im mu")
    plane.grid(alpha=0.3)
    plane.set_title("multipliers and the unit circle", fontsize=9)
    polar.set_xlim(-185.0, 185.0)
    polar.set_xticks([-180, -90, 0, 90, 180])
    polar.set_xlabel("arg mu [deg] (+-180: through -1, 0: through +1)")
    polar.set_ylabel("|mu|")
    polar.grid(alpha=0.3)
    fig.legend(*polar.get_legend_handles_labels(), fontsize=7, loc="lower center", ncol=2, frameon=False)
    fig.suptitle(title or f"Floquet multipliers over the base period at {len(points)} points "
                 f"({curve.response.stability.method if curve.response.stability is not None else 'no stability'})",
                 fontsize=10)
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


def static_te_figure(table, title: str):
    """Figure: loaded TE, pair loads and stiffness against the mesh phase, one colour per torque."""
    fig = _figure(figsize=(8, 8))
    ax_te, ax_load, ax_k = fig.subplots(3, 1, sharex=True)
    styles = ("-", "--", ":", "-.")
    for i, torque in enumerate(table.torque_pinion_Nm):
        color = f"C{i % 10}"
        ax_te.plot(table.phase, 1e6 * table.delta_m[i], color=color, label=f"{torque:g} N m")
        ax_k.plot(table.phase, 1e-6 * table.mesh_stiffness_N_per_m[i], color=color,
                  label="mesh, dN/d delta" if i == 0 else None)
        for j in range(table.in_contact.shape[0]):
            contact = table.in_contact[j]
            style = styles[j % len(styles)]
            ax_load.plot(table.phase[contact], table.pair_loads_N[i, j][contact], style, color=color,
                         label=f"pair {j + 1}" if i == 0 else None)
            if i == 0:
                ax_k.plot(table.phase[contact], 1e-6 * table.pair_stiffness_N_per_m[0, j][contact], style,
                          color="0.5", lw=1.0, label=f"pair {j + 1}, k_j")
    ax_te.set_ylabel("loaded static TE [um]")
    ax_load.set_ylabel("pair load [N]")
    ax_k.set_ylabel("stiffness [MN/m]")
    ax_k.set_xlabel("mesh phase [-]")
    for ax in (ax_te, ax_load, ax_k):
        ax.legend(fontsize=8, loc="best")
        ax.grid(alpha=0.3)
    ax_te.set_title(title, fontsize=10)
    fig.tight_layout()
    return fig


def harris_figure(torques_Nm, p2p_um, design_torque_Nm: float, title: str):
    """Figure: the Harris map, loaded TE peak-to-peak against pinion torque."""
    order = np.argsort(torques_Nm)
    fig = _figure(figsize=(7, 4.5))
    ax = fig.subplots()
    ax.plot(np.asarray(torques_Nm)[order], np.asarray(p2p_um)[order], "o-", color="k")
    ax.axvline(design_torque_Nm, color="tab:blue", ls="--", lw=1.0, label=f"[load] torque {design_torque_Nm:g} N m")
    ax.set_xlabel("pinion torque [N m]")
    ax.set_ylabel("loaded static TE peak-to-peak [um]")
    ax.set_ylim(bottom=0.0)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    return fig
