"""One operating point and the frequency-response curve of the gear pair, with what a gear engineer reads.

:func:`solve` and :func:`frequency_response` are the gear-pair forms of
:mod:`hbgear.engine.response`: pinion speeds instead of a parameter, the staged start of
:func:`~hbgear.gear.solve.solve_periodic` (quasi-static state, the LTV solution, smoothing
continuation) where Newton from a guess does not do, ``harmonics = None`` for the automatic
count, the rule that decides when ``nu = 2`` branches are followed, and the read-outs of every
point (DTE mean/RMS/peak-to-peak, dynamic factor) in the units of ``frc.csv``, the DTE at mesh
orders (``orders.csv``), the points whose Floquet multipliers ``floquet.png`` shows, and the
ISO 6336-1 resonance speed of the pair.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from ..engine.response import FrequencyResponse, solution_multipliers
from ..engine.response import frequency_response as engine_frequency_response
from .model import GearPairModel
from .readouts import BEARING_FORCES, bearing_keys, bearing_weights, order_amplitudes
from .resonance import ResonanceRanges, iso6336_resonance
from .solve import PeriodicSolution, auto_harmonics, rad_s_to_rpm, read_outs, solve_periodic, start_guess
from .system import GearSystem

__all__ = ["BEARING_COLUMNS", "COLUMNS", "DEFAULT_ORDERS", "columns", "FLOQUET_COLUMNS", "FLOQUET_POINTS", "ORDER_KEY_COLUMNS",
           "PD_AUTO_MAX_UNKNOWNS", "GearFrequencyResponse", "frequency_response", "order_column", "period_doubling_rule",
           "solve", "unstable_zones"]

#: Columns of ``frc.csv`` (and of :meth:`GearFrequencyResponse.table`), in order.
COLUMNS = ("speed_rpm", "mesh_freq_hz", "dte_mean_um", "dte_rms_um", "dte_p2p_um", "dynamic_factor",
           "max_abs_floquet", "stable", "nu", "residual")

#: Columns ``frc.csv`` gains on bearings (INTERFACE.md "Bearings"): the RMS of each bearing force.
BEARING_COLUMNS = bearing_keys(("rms",))


def columns(model: GearPairModel) -> tuple:
    """The ``frc.csv`` columns of `model`: :data:`COLUMNS`, then :data:`BEARING_COLUMNS` on bearings."""
    return COLUMNS + (BEARING_COLUMNS if model.bearings is not None else ())

#: Columns of ``floquet.csv``: one row per multiplier of every ``nu = 1`` point, ``row`` the
#: point's data row in ``frc.csv`` (0 = first), multipliers over the base period, largest first.
FLOQUET_COLUMNS = ("row", "speed_rpm", "index", "multiplier_re", "multiplier_im", "multiplier_abs")

#: The first columns of ``orders.csv`` (one row per ``frc.csv`` row, ``row`` its index from 0);
#: the amplitude columns follow, named by :func:`order_column`.
ORDER_KEY_COLUMNS = ("row", "speed_rpm", "mesh_freq_hz", "nu")

#: Mesh orders of ``orders.csv`` by default: ``1 .. min(H / nu, DEFAULT_ORDERS)``.
DEFAULT_ORDERS = 10

#: At most this many points in ``floquet.png`` (:meth:`GearFrequencyResponse.floquet_points`).
FLOQUET_POINTS = 6


def order_column(order: float, quantity: str = "dte", unit: str = "um") -> str:
    """The ``orders.csv`` column of `quantity` at a mesh order: ``dte_order_2_um``, and for a half
    order the point written ``p`` (``dte_order_0p5_um``, ``dte_order_1p5_um``)."""
    return f"{quantity}_order_{float(order):g}_{unit}".replace(".", "p")


#: The ``nu = 2`` branches of a ``nu = 1`` curve are followed by default (``"auto"``) when the
#: model is non-linear in its contact (backlash bounds the branch) and the ``nu = 2`` problem has
#: at most this many unknowns, ``ndof (4 H + 1)`` (its basis has ``H2 = 2 H`` harmonics of
#: ``w_m / 2``). Each ``nu = 2`` point costs a Jacobian of that size per Newton step and, where
#: the teeth separate, a Hill eigenproblem of twice that size: measured on 2 cores ~0.02 s at 65
#: unknowns, ~0.2 s at 194, ~0.9 s at 386, so at the limit a branch of ~100 points costs about as
#: much as the ``nu = 1`` curve's stability. (A linear model has no bounded ``nu = 2`` branch:
#: its crossings are located, never followed.)
PD_AUTO_MAX_UNKNOWNS = 200


def period_doubling_rule(model: GearPairModel, harmonics: int, nu: int, flag=None) -> tuple[bool, bool, str]:
    """``(locate the crossings?, follow the nu = 2 branches?, why)``.

    `flag`: ``True`` (follow), ``False`` (off), ``None`` / ``"auto"`` (the rule: follow where the
    teeth can separate, backlash bounding the branch, and the ``nu = 2`` problem has at most
    :data:`PD_AUTO_MAX_UNKNOWNS` unknowns). Only ``nu = 1`` curves are searched.
    """
    if nu != 1:
        return False, False, f"period doublings are only looked for on nu = 1 curves (this one has nu = {nu})"
    if isinstance(flag, str):
        flag = None if flag.strip().lower() == "auto" else flag.strip().lower() in ("true", "on", "yes", "1")
    if flag is False:
        return False, False, "off"
    if model.is_linear:
        return True, False, ("crossings located; a linear model has no bounded nu = 2 branch to follow "
                             "(the response grows without bound inside the instability tongue)")
    if flag:
        return True, True, "on"
    if model.mesh_is_linear:
        return True, False, ("auto: crossings located, nu = 2 branches not followed: without backlash the mesh "
                             "stays linear and only the friction limits the branch, which grows like a linear "
                             "model's (NLTV pair, H = 16: DTE 12 -> 528 um peak-to-peak within 3 rpm, not ended "
                             "in 4000 points); --period-doubling to force")
    unknowns = model.ndof * (4 * harmonics + 1)
    if unknowns <= PD_AUTO_MAX_UNKNOWNS:
        return True, True, f"auto: on (nu = 2 problem of {unknowns} <= {PD_AUTO_MAX_UNKNOWNS} unknowns)"
    return True, False, (f"auto: crossings located, nu = 2 branches not followed (nu = 2 problem of {unknowns} > "
                         f"{PD_AUTO_MAX_UNKNOWNS} unknowns; --period-doubling to force)")


def solve(model: GearPairModel, omega: float, *, harmonics: int | None = 24, nu: int = 1, samples: int | None = None,
          tolerance: float = 1e-9, max_iterations: int = 50, z0=None, stability: bool = True) -> PeriodicSolution:
    """The periodic steady state at pinion speed `omega` [rad/s] (``harmonics = None``: the
    automatic count of :func:`~hbgear.gear.solve.auto_harmonics`), with its Floquet multipliers
    (exact monodromy where the model is linear along the solution, else Hill's method).

    **Raises:** :class:`~hbgear.errors.ConvergenceError` (where, what was tried, the residual).
    """
    if harmonics is None:
        sol = auto_harmonics(model, omega, nu=nu, tolerance=tolerance, max_iterations=max_iterations)
    else:
        sol = solve_periodic(model, omega, harmonics=harmonics, nu=nu, samples=samples, tolerance=tolerance,
                             max_iterations=max_iterations, z0=z0)
    if not stability:
        return sol
    return sol.with_multipliers(solution_multipliers(sol.hb, sol.system, sol.z, sol.omega_pinion))


def _harmonics(model, omega_start, omega_stop, harmonics, nu, samples, tolerance, max_iterations):
    """``(H, samples, start solution or None, rule text)``; with ``harmonics = None`` the automatic
    count at both ends of the sweep, the larger used for the whole curve."""
    if harmonics is not None:
        samples = samples if samples is not None else max(1024, 4 * harmonics * nu + 2)
        return harmonics, samples + samples % nu, None, f"from the config ({harmonics})"
    kw = dict(nu=nu, tolerance=tolerance, max_iterations=max_iterations)
    at_start, at_stop = auto_harmonics(model, omega_start, **kw), auto_harmonics(model, omega_stop, **kw)
    harmonics = max(at_start.harmonics, at_stop.harmonics)
    samples = max(1024 if samples is None else samples, 4 * harmonics * nu)
    samples += samples % nu
    start = solve_periodic(model, omega_start, harmonics=harmonics, nu=nu, samples=samples, tolerance=tolerance,
                           max_iterations=max_iterations)
    text = (f"auto: hbgear.gear.solve.auto_harmonics gave H = {at_start.harmonics} at the start speed and "
            f"{at_stop.harmonics} at the stop speed; the larger is used")
    return harmonics, samples, start, text


@dataclass(frozen=True)
class GearFrequencyResponse:
    """The gear pair's frequency-response curve.

    **Fields:** `model`; `response` (the engine's :class:`~hbgear.engine.response.FrequencyResponse`
    of the ``nu`` branch: unknowns, Floquet multipliers, folds, period doublings, ``nu = 2``
    branches); `speed_rpm_range` ``(start, stop)``; `table` (the ``frc.csv`` columns,
    :data:`COLUMNS`, as arrays: the ``nu`` branch in path order, then each ``nu = 2`` branch in
    path order from its bifurcation); `harmonics_rule`, `period_doubling_rule`, `zones_rule` (how
    they were decided); `timings_s`.

    **Derived:** the columns as attributes (`speed_rpm`, `dte_rms_um`, `stable`, `nu`, ...),
    `folds` (fold speeds [rpm]), `fold_records`, `period_doublings` and `unstable_zones` (in rpm),
    `resonance` (ISO 6336-1 ``n_E1`` and its ranges), :meth:`rows` (``frc.csv`` dicts),
    :meth:`floquet_rows`, :meth:`mesh_orders`, :meth:`order_amplitudes_um`, :meth:`order_rows`
    (``orders.csv``), :meth:`floquet_points`, :meth:`solution`.
    """

    model: GearPairModel
    response: FrequencyResponse
    speed_rpm_range: tuple
    table: dict
    harmonics_rule: str = ""
    period_doubling_rule: str = ""
    zones_rule: str = ""
    timings_s: dict = field(default_factory=dict)

    speed_rpm = property(lambda self: self.table["speed_rpm"], doc="pinion speed [rpm], every row")
    mesh_freq_hz = property(lambda self: self.table["mesh_freq_hz"], doc="mesh frequency [Hz], every row")
    dte_mean_um = property(lambda self: self.table["dte_mean_um"], doc="mean DTE [um], every row")
    dte_rms_um = property(lambda self: self.table["dte_rms_um"], doc="RMS of the DTE about its mean [um], every row")
    dte_p2p_um = property(lambda self: self.table["dte_p2p_um"], doc="DTE peak-to-peak [um], every row")
    dynamic_factor = property(lambda self: self.table["dynamic_factor"], doc="max F_mesh / N, every row")
    max_abs_floquet = property(lambda self: self.table["max_abs_floquet"], doc="max |multiplier| over the base period")
    stable = property(lambda self: self.table["stable"], doc="1 stable, 0 unstable, NaN unknown, every row")
    nu = property(lambda self: self.table["nu"], doc="1 on the main branch, 2 on period-doubled rows")
    residual = property(lambda self: self.table["residual"], doc="scaled residual max-norm, every row")

    def __len__(self) -> int:
        return len(self.table["speed_rpm"])

    @property
    def success(self) -> bool:
        return self.response.success

    @property
    def harmonics(self) -> int:
        return self.response.hb.harmonics

    @property
    def points(self) -> int:
        """Points of the ``nu`` branch (the first rows of the table)."""
        return len(self.response)

    @property
    def folds(self) -> np.ndarray:
        """Speeds [rpm] of the located folds."""
        return self.table["speed_rpm"][self.response.branch.folds]

    @property
    def fold_records(self) -> list[dict]:
        b = self.response.branch
        return [{"index": int(i), "speed_rpm": float(self.speed_rpm[i]), "mesh_freq_hz": float(self.mesh_freq_hz[i]),
                 "dte_rms_um": float(self.dte_rms_um[i]), "dte_p2p_um": float(self.dte_p2p_um[i]),
                 "kind": "maximum speed" if b.tangent_p[i - 1] > 0 else "minimum speed"} for i in b.folds]

    @property
    def unstable_zones(self) -> list[dict]:
        """The exact scan's zones (linear models), speeds in rpm (:func:`unstable_zones`)."""
        return [_zone_in_rpm(z) for z in self.response.unstable_zones]

    @property
    def period_doublings(self) -> list[dict]:
        """One record per located -1 crossing (speeds in rpm; the ``nu = 2`` branch's rows in the table)."""
        return _pd_records(self)

    @property
    def columns(self) -> tuple:
        """The ``frc.csv`` columns of this curve (:func:`columns`)."""
        return columns(self.model)

    def rows(self) -> list[dict]:
        """The ``frc.csv`` rows as dicts (``stable`` and ``nu`` as integers; ``stable`` NaN where unknown)."""
        out = []
        cols = self.columns
        for i in range(len(self)):
            row = {k: float(self.table[k][i]) for k in cols}
            row["nu"] = int(row["nu"])
            if not math.isnan(row["stable"]):
                row["stable"] = int(row["stable"])
            out.append(row)
        return out

    def floquet_rows(self) -> list[list]:
        """The ``floquet.csv`` rows (:data:`FLOQUET_COLUMNS`) of the ``nu`` branch's points."""
        rows = []
        for row, (rpm, mult) in enumerate(zip(self.speed_rpm[:self.points], self.response.multipliers)):
            if mult is None:
                continue
            mult = np.asarray(mult, dtype=complex)
            for k, m in enumerate(mult[np.argsort(-np.abs(mult), kind="stable")]):
                rows.append([row, float(rpm), k, float(m.real), float(m.imag), float(abs(m))])
        return rows

    @property
    def resonance(self) -> ResonanceRanges:
        """The ISO 6336-1 main resonance speed ``n_E1`` of the pair and its speed ranges
        (:func:`~hbgear.gear.resonance.iso6336_resonance`)."""
        return iso6336_resonance(self.model)

    def mesh_orders(self, count: int | None = None) -> np.ndarray:
        """The mesh orders of ``orders.csv``: ``1 .. K``, ``K = count`` (default
        ``min(H // nu, DEFAULT_ORDERS)`` of the ``nu`` branch), then the half orders
        ``0.5 .. K - 0.5`` when any row repeats over two mesh periods (``nu = 2``).

        **Raises:** ``ValueError`` when ``K nu > H`` (order ``K`` not in the curve's basis).
        """
        hb = self.response.hb
        limit = hb.harmonics // hb.nu
        k = min(limit, DEFAULT_ORDERS) if count is None else int(count)
        if not 1 <= k <= limit:
            raise ValueError(f"{k} mesh orders: between 1 and H // nu = {limit} (H = {hb.harmonics}, nu = {hb.nu})")
        orders = np.arange(1.0, k + 1.0)
        return np.concatenate([orders, orders - 0.5]) if np.any(self.nu == 2) else orders

    def order_amplitudes_um(self, orders=None) -> np.ndarray:
        """DTE amplitude [um] at each mesh order (default :meth:`mesh_orders`) of every row of the
        table, shape ``(rows, orders)``, straight from the harmonic-balance coefficients
        (:func:`~hbgear.gear.readouts.order_amplitudes`); 0 at half orders on ``nu = 1`` rows."""
        orders = self.mesh_orders() if orders is None else np.asarray(orders, dtype=float)
        r = self.response
        parts = [(r.hb, r.branch.z)] + [(d.hb, d.z) for d in r.doubled]
        amplitudes = [1e6 * order_amplitudes(hb.decode(r.system, z)[0], hb.nu, orders)
                      for hb, z in parts if len(z)]
        return np.concatenate(amplitudes) if amplitudes else np.zeros((0, len(orders)))

    def bearing_order_amplitudes_N(self, orders=None) -> dict:
        """Each bearing force's amplitude [N] at the mesh orders (default :meth:`mesh_orders`) of every
        row: name -> ``(rows, orders)`` (one :func:`~hbgear.gear.readouts.order_amplitudes` call per
        force, ``w.q + v.q'``); empty with rigid bearings."""
        orders = self.mesh_orders() if orders is None else np.asarray(orders, dtype=float)
        r, out = self.response, {}
        parts = [(r.hb, r.branch.z, r.branch.p)] + [(d.hb, d.z, d.p) for d in r.doubled]
        for name, (w, v, _) in bearing_weights(self.model).items():
            amplitudes = [order_amplitudes(hb.decode(r.system, z)[0], hb.nu, orders, w, v,
                                           np.asarray(p) * self.model.teeth_pinion / hb.nu)
                          for hb, z, p in parts if len(z)]
            out[name] = np.concatenate(amplitudes) if amplitudes else np.zeros((0, len(orders)))
        return out

    def order_rows(self, orders=None) -> tuple[list[str], list[list]]:
        """``orders.csv``: the header (:data:`ORDER_KEY_COLUMNS`, then :func:`order_column` of each
        order; on bearings then each bearing force's orders, ``bearing_force_<gear>_<direction>_order_<r>_N``)
        and one row per ``frc.csv`` row, in its order."""
        orders = self.mesh_orders() if orders is None else np.asarray(orders, dtype=float)
        amplitudes = self.order_amplitudes_um(orders)
        header = [*ORDER_KEY_COLUMNS, *(order_column(o) for o in orders)]
        bearing = self.bearing_order_amplitudes_N(orders)
        for name in BEARING_FORCES:
            if name in bearing:
                amplitudes = np.concatenate([amplitudes, bearing[name]], axis=1)
                header += [order_column(o, f"bearing_force_{name}", "N") for o in orders]
        speed, freq, nu = self.speed_rpm, self.mesh_freq_hz, self.nu
        rows = [[i, float(speed[i]), float(freq[i]), int(nu[i]), *amplitudes[i].tolist()] for i in range(len(self))]
        return header, rows

    def floquet_points(self, limit: int = FLOQUET_POINTS) -> list[dict]:
        """The points of the ``nu`` branch whose multipliers ``floquet.png`` shows: at most `limit`
        with known multipliers, taken in this order (a point already taken is skipped):

        1. the most unstable point (largest ``max |multiplier|``), if any point is unstable;
        2. the stable point of largest DTE peak-to-peak (the resonance peak, where it is stable);
        3. at each located period doubling, in path order, the curve point on its unstable side;
        4. each fold point;
        5. at each period doubling, the curve point on its stable side.

        **Returns:** dicts ``row`` (the ``frc.csv`` row), ``speed_rpm``, ``max_abs_floquet``,
        ``reason``, sorted by speed.
        """
        n, r = self.points, self.response
        known = [i for i in range(n) if r.multipliers[i] is not None and np.size(r.multipliers[i])]
        usable, picks = set(known), {}

        def take(i, reason):
            if i in usable and i not in picks and len(picks) < limit:
                picks[i] = reason

        def sides(rec):
            """``(unstable-side row, stable-side row)`` of a crossing's bracket."""
            i, j = rec["bracket_rows"]
            higher, lower = (j, i) if r.branch.p[j] > r.branch.p[i] else (i, j)
            return (higher, lower) if rec["unstable_side"] == "above" else (lower, higher)

        stable, max_abs = self.stable[:n], self.max_abs_floquet[:n]
        unstable = [i for i in known if stable[i] == 0]
        if unstable:
            take(max(unstable, key=lambda i: max_abs[i]), "most unstable")
        stable_points = [i for i in known if stable[i] == 1]
        if stable_points:
            take(max(stable_points, key=lambda i: self.dte_p2p_um[i]), "stable, largest DTE")
        crossings = [(sides(rec), rad_s_to_rpm(rec["parameter"])) for rec in r.period_doublings if "parameter" in rec]
        for (row, _), rpm in crossings:
            take(row, f"unstable side of the period doubling at {rpm:.6g} rpm")
        for i in r.branch.folds:
            take(int(i), "fold")
        for (_, row), rpm in crossings:
            take(row, f"stable side of the period doubling at {rpm:.6g} rpm")
        return [{"row": int(i), "speed_rpm": float(self.speed_rpm[i]), "max_abs_floquet": float(max_abs[i]),
                 "reason": picks[i]} for i in sorted(picks, key=lambda i: self.speed_rpm[i])]

    def solution(self, i: int) -> PeriodicSolution:
        """Point `i` of the ``nu`` branch as a :class:`~hbgear.gear.solve.PeriodicSolution`."""
        r = self.response
        m = None if r.stability is None else r.stability.multipliers[i]
        return PeriodicSolution.from_z(self.model, float(r.branch.p[i]), r.branch.z[i], r.hb,
                                       residual_norm=float(r.branch.residual[i]), multipliers=m)


def _zone_in_rpm(zone: dict) -> dict:
    return {"speed_rpm_from": rad_s_to_rpm(zone["parameter_from"]), "speed_rpm_to": rad_s_to_rpm(zone["parameter_to"]),
            "max_abs_floquet": zone["max_abs_floquet"], "multiplier": zone["multiplier"],
            "leaves_through": zone["leaves_through"], "resolution_rpm": rad_s_to_rpm(zone["resolution"]),
            "between_curve_points": zone["between_points"]}


def unstable_zones(model: GearPairModel, omegas, subdivisions: int = 6) -> list[dict]:
    """Speed intervals where a linear model's steady state is unstable, by exact monodromy on a grid
    `subdivisions` times finer than the speeds `omegas` [rad/s]
    (:func:`hbgear.engine.stability.unstable_zones`): ``speed_rpm_from``, ``speed_rpm_to``,
    ``max_abs_floquet``, ``multiplier``, ``leaves_through``, ``resolution_rpm``,
    ``between_curve_points``."""
    from ..engine.stability import unstable_zones as scan

    return [_zone_in_rpm(z) for z in scan(GearSystem(model), omegas, subdivisions)]


#: The read-outs among the ``frc.csv`` columns (only these are evaluated for a curve).
_READ_OUT_COLUMNS = ("dte_mean_um", "dte_rms_um", "dte_p2p_um", "dynamic_factor")


def _table(model, p, zs, hb, max_abs, stable, nu, residual, speed_rpm=None) -> dict:
    """The frc.csv columns of a set of points (read-outs batched, only those of the columns)."""
    supports = bearing_keys() + ("mean_bearing_loss_W",) if model.bearings is not None else ()
    read = read_outs(model, p, zs, hb, keys=_READ_OUT_COLUMNS + supports)
    speed = rad_s_to_rpm(np.asarray(p, dtype=float)) if speed_rpm is None else speed_rpm
    return {"speed_rpm": np.asarray(speed, dtype=float), "mesh_freq_hz": np.asarray(p) * model.teeth_pinion / (2 * math.pi),
            **read,
            "max_abs_floquet": np.asarray(max_abs, dtype=float), "stable": np.asarray(stable, dtype=float),
            "nu": np.full(len(p), nu, dtype=float), "residual": np.asarray(residual, dtype=float),
            **{k: read[k] for k in read if k.startswith("bearing_force_")},
            **{k: read[k] for k in ("mean_bearing_loss_W",) if k in read}}


def _pd_records(curve: GearFrequencyResponse) -> list[dict]:
    r = curve.response
    first = curve.points
    firsts = []
    for d in r.doubled:
        firsts.append(first)
        first += len(d.p)
    status_text = {"reached range end": "reached sweep end"}
    out = []
    for rec in r.period_doublings:
        rpm = [rad_s_to_rpm(rec["bracket"][0]), rad_s_to_rpm(rec["bracket"][1])]
        item = {"bracket_rpm": rpm, "bracket_rows": rec["bracket_rows"], "unstable_side": rec["unstable_side"]}
        if "parameter" in rec:
            item.update(speed_rpm=rad_s_to_rpm(rec["parameter"]),
                        mesh_freq_hz=rec["parameter"] * curve.model.teeth_pinion / (2 * math.pi),
                        multiplier=rec["multiplier"])
        item.update(status=status_text.get(rec["status"], rec["status"]), message=rec["message"], points=0)
        k = rec.get("branch")
        if k is not None:
            d, stab = r.doubled[k], r.doubled_stability[k]
            rows = slice(firsts[k], firsts[k] + len(d.p))
            speeds, p2p = curve.speed_rpm[rows], curve.dte_p2p_um[rows]
            item.update(points=len(d.p), harmonics=d.hb.harmonics, time_samples=d.hb.samples, first_row=firsts[k],
                        speed_rpm_range=[float(speeds.min()), float(speeds.max())] if len(d.p) else None,
                        dte_p2p_um_range=[float(p2p.min()), float(p2p.max())] if len(d.p) else None,
                        unstable_points=int(np.sum(stab.stable == 0)), stability_method=stab.method,
                        stability_warning=stab.warning)
        item["time_s"] = rec.get("time_s", 0.0)
        out.append(item)
    return out


def frequency_response(model: GearPairModel, omega_start: float, omega_stop: float, *, harmonics: int | None = 24,
                       nu: int = 1, samples: int | None = None, tolerance: float = 1e-9, max_iterations: int = 50,
                       max_points: int = 4000, step: float | None = None, stability: bool = True,
                       period_doubling=None, progress=None,
                       speed_rpm_range: tuple | None = None) -> GearFrequencyResponse:
    """The frequency-response curve from `omega_start` to `omega_stop` [rad/s] by arclength
    continuation in the pinion speed (either end may be the larger; folds followed and located).

    **Arguments:** `harmonics` (``None``: automatic, the larger count of both ends), `nu`,
    `samples` (AFT, default ``max(1024, 4 H nu + 2)``), `tolerance`, `max_iterations` (Newton per
    start), `max_points`, `step` [rad/s] (first step), `stability` (Floquet multipliers of every
    point, the exact zone scan for linear models), `period_doubling` (``True`` follow the
    ``nu = 2`` branches, ``False`` off, ``None``/``"auto"``: :func:`period_doubling_rule`),
    `progress` (bars; ``None``: only on a terminal), `speed_rpm_range` (the exact end speeds in
    rpm for the table, as the user gave them).

    **Returns:** a :class:`GearFrequencyResponse`; when the continuation stops early the curve so
    far is returned with ``success`` False and the message (never silently as complete).
    """
    t0 = time.perf_counter()
    harmonics, samples, start, rule = _harmonics(model, omega_start, omega_stop, harmonics, nu, samples, tolerance,
                                                 max_iterations)
    system = GearSystem(model)
    hb_guess = _hb(model, harmonics, nu, samples)
    guess = start_guess(model, hb_guess, system) if start is None else np.asarray(start.z)

    def staged_start(omega):
        return np.asarray(solve_periodic(model, omega, harmonics=harmonics, nu=nu, samples=samples, tolerance=tolerance,
                                         max_iterations=max_iterations).z)

    if guess is None:  # no guess for backlash models: the staged start at once
        guess = staged_start(omega_start)
    t_start = time.perf_counter() - t0
    look, follow, pd_rule = period_doubling_rule(model, harmonics, nu, period_doubling)
    if not stability and look:
        look, follow, pd_rule = False, False, "period doublings not looked for: no Floquet multipliers (stability off)"
    response = engine_frequency_response(
        system, (omega_start, omega_stop), harmonics=harmonics, nu=nu, samples=samples, tolerance=tolerance,
        max_iterations=max_iterations, max_points=max_points, step=step, z0=guess, start=staged_start,
        stability=stability, period_doubling=("follow" if follow else "locate") if look else False, progress=progress)
    b = response.branch
    speed = rad_s_to_rpm(np.asarray(b.p, dtype=float))
    if speed_rpm_range is not None and len(speed):
        speed[0] = speed_rpm_range[0]  # exact ends (no rpm -> rad/s -> rpm rounding)
        if b.success:
            speed[-1] = speed_rpm_range[1]
    t_table = time.perf_counter()
    parts = [_table(model, b.p, b.z, response.hb, response.max_abs_floquet, response.stable, nu, b.residual, speed)]
    for d, stab in zip(response.doubled, response.doubled_stability):
        parts.append(_table(model, d.p, d.z, d.hb, stab.max_abs, stab.stable, 2, d.residual))
    table = {k: np.concatenate([t[k] for t in parts]) for k in parts[0]}
    t_table = time.perf_counter() - t_table
    if not stability:
        zones_rule = "not scanned (stability off)"
    elif model.is_linear and len(b) > 1:
        zones_rule = ("exact monodromy on a grid 6x finer than the curve's points (linear model); zones narrower than "
                      "the grid step can still be missed")
    else:
        zones_rule = "not scanned: the model is not linear (zones are the unstable curve points)"
    rng = speed_rpm_range if speed_rpm_range is not None else (rad_s_to_rpm(omega_start), rad_s_to_rpm(omega_stop))
    return GearFrequencyResponse(model, response, tuple(rng), table, rule, pd_rule, zones_rule,
                                 {"start_solution": t_start} | dict(response.timings_s) | {"read_outs": t_table})


def _hb(model, harmonics, nu, samples):
    from ..engine.hb import HarmonicBalance

    return HarmonicBalance(model.ndof, harmonics, nu, samples)
