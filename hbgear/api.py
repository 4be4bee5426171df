"""The Python API: one call per job, for the gear pair (speeds in rpm) or any periodic system.

>>> import hbgear
>>> model = hbgear.build_model(hbgear.load_config("examples/paper_table1.toml"))
>>> sol = hbgear.solve(model, speed_rpm=5000.0, harmonics=32)          # doctest: +SKIP
>>> curve = hbgear.frequency_response(model, speed_rpm=(3000.0, 20000.0))  # doctest: +SKIP

The same calls take a :class:`~hbgear.engine.system.PeriodicSystem` with ``parameter=`` instead
of ``speed_rpm=``. The command-line tool is a thin layer over these functions.
"""

from __future__ import annotations

import numpy as np

from .engine import response as _engine
from .engine.system import PeriodicSystem
from .gear import response as _gear
from .gear.model import GearPairModel
from .gear.solve import PeriodicSolution, rpm_to_rad_s

__all__ = ["FrequencyResponse", "PeriodicSolution", "SystemFrequencyResponse", "dataframe", "frc_curve",
           "frequency_response", "natural_frequencies", "simulate", "solve", "stability_map"]


def natural_frequencies(model: GearPairModel):
    """Natural frequencies and modes of the gear pair's linear time-invariant model (mean mesh
    stiffness, no friction, no damping): a :class:`~hbgear.gear.modes.Modes`
    (:func:`hbgear.gear.modes.natural_frequencies`)."""
    from .gear.modes import natural_frequencies as modes

    return modes(model)


def dataframe(columns):
    """A :class:`pandas.DataFrame` of `columns` (``{name: values}``, in order); pandas is optional.

    **Raises:** ``ImportError`` with what to install when pandas is missing.
    """
    try:
        import pandas
    except ImportError:
        raise ImportError("to_dataframe() needs pandas, which hbgear does not depend on: pip install pandas "
                          "(the same data without it: .rows() or the arrays)") from None
    return pandas.DataFrame({k: list(v) if isinstance(v, (list, tuple)) else v for k, v in columns.items()})


class FrequencyResponse(_gear.GearFrequencyResponse):
    """The gear pair's frequency-response curve (:class:`~hbgear.gear.response.GearFrequencyResponse`)
    with its picture: :meth:`plot` -> the ``frc.png`` figure."""

    def plot(self, title: str | None = None):
        """Matplotlib figure: DTE RMS and peak-to-peak against speed (and mesh frequency), unstable
        points, folds, ``nu = 2`` branches, period doublings, unstable zones."""
        from .outputs.plots import frc_figure

        return frc_figure(self, title)

    def plot_orders(self, orders=None, title: str | None = None):
        """The ``orders.png`` figure: DTE order lines against speed and the speed x order map (dB re 1 um)."""
        from .outputs.plots import orders_figure

        orders = self.mesh_orders() if orders is None else orders
        return orders_figure(self, orders, self.order_amplitudes_um(orders), self.resonance, title)

    def plot_bearing_orders(self, name: str, orders=None, title: str | None = None, amplitudes_N=None):
        """Order tracking of one bearing force (`name`: ``pinion_loa``, ``pinion_oloa``, ``gear_loa``,
        ``gear_oloa``; on bearings only), as :meth:`plot_orders` in N (``bearing_orders_<name>.png``).
        `amplitudes_N`: :meth:`bearing_order_amplitudes_N` at `orders`, when already computed."""
        from .outputs.plots import orders_figure

        orders = self.mesh_orders() if orders is None else orders
        amplitudes = self.bearing_order_amplitudes_N(orders) if amplitudes_N is None else amplitudes_N
        if name not in amplitudes:
            raise ValueError(f"no bearing force {name!r} on this model; it has {sorted(amplitudes) or 'none'}")
        gear, direction = name.split("_")
        return orders_figure(self, orders, amplitudes[name], self.resonance, title,
                             quantity=f"{gear} {direction.upper()} bearing force", unit="N")

    def plot_dynamic_factor(self, title: str | None = None):
        """The ``dynamic_factor.png`` figure: ``max F_mesh / N`` against speed with ISO 6336-1's ``n_E1`` and ranges."""
        from .outputs.plots import dynamic_factor_figure

        return dynamic_factor_figure(self, self.resonance, title)

    def plot_floquet(self, points=None, title: str | None = None):
        """The ``floquet.png`` figure: the multipliers of :meth:`floquet_points` (or `points`) and the unit circle."""
        from .outputs.plots import floquet_figure

        return floquet_figure(self, self.floquet_points() if points is None else points, title)

    def to_dataframe(self):
        """The ``frc.csv`` table as a :class:`pandas.DataFrame` (pandas is not a dependency)."""
        return dataframe({k: self.table[k] for k in self.columns})

    def plot_bearing_forces(self, title: str | None = None):
        """The ``bearing_forces.png`` figure: RMS of the LOA and OLOA bearing forces of pinion and gear
        against speed (models on bearings)."""
        from .outputs.plots import bearing_forces_figure

        return bearing_forces_figure(self, title)

    def natural_frequencies(self):
        """The :class:`~hbgear.gear.modes.Modes` of the curve's model (:func:`natural_frequencies`)."""
        return natural_frequencies(self.model)

    def plot_campbell(self, orders: int = 10, title: str | None = None):
        """The ``campbell.png`` figure: mesh orders ``1..orders`` against speed and the natural
        frequencies of the mean-stiffness model as horizontal lines (their crossings marked)."""
        from .outputs.plots import campbell_figure

        return campbell_figure(self.natural_frequencies(), self.model, self.speed_rpm_range, orders, title)


class SystemFrequencyResponse(_engine.FrequencyResponse):
    """A periodic system's curve (:class:`~hbgear.engine.response.FrequencyResponse`) with :meth:`plot`."""

    def plot(self, coordinate: int = 0, title: str | None = None):
        """Matplotlib figure: ``max |q_i(t)|`` against the parameter, unstable points red, folds marked."""
        from .outputs.plots import system_curve_figure

        return system_curve_figure(self, coordinate, title)


def _check_target(target, speed_rpm, parameter, what: str):
    if isinstance(target, GearPairModel):
        if speed_rpm is None or parameter is not None:
            raise TypeError(f"{what} of a gear pair takes speed_rpm= (and not parameter=)")
        return True
    if isinstance(target, PeriodicSystem):
        if parameter is None or speed_rpm is not None:
            raise TypeError(f"{what} of a PeriodicSystem takes parameter= (and not speed_rpm=)")
        return False
    raise TypeError(f"{what} takes a GearPairModel (hbgear.build_model) or a hbgear.PeriodicSystem, "
                    f"not {type(target).__name__}")


def _harmonics(harmonics):
    if isinstance(harmonics, str):
        if harmonics.strip().lower() != "auto":
            raise ValueError(f"harmonics = {harmonics!r}: an integer >= 1 or 'auto'")
        return None
    return harmonics


def solve(target, *, speed_rpm: float | None = None, parameter: float | None = None, harmonics=24, nu: int = 1,
          samples: int | None = None, tolerance: float = 1e-9, max_iterations: int = 50, z0=None,
          stability: bool = True):
    """One periodic solution by harmonic balance, with its Floquet multipliers.

    **Arguments:** `target`: a gear-pair model (then `speed_rpm`, the pinion speed [rpm]) or a
    :class:`~hbgear.engine.system.PeriodicSystem` (then `parameter`); `harmonics` ``H`` (gear pair:
    also ``"auto"``, grown until the top harmonics are negligible); `nu` (2 adds half orders);
    `samples` (AFT samples per base period, default ``max(1024, 4 H nu + 2)``); `tolerance` (on
    the scaled residual); `max_iterations` (Newton); `z0` (start unknowns); `stability`
    (multipliers: exact monodromy where the system is linear along the solution, else Hill).

    **Returns:** a :class:`~hbgear.gear.solve.PeriodicSolution` (gear pair: ``.summary()``,
    ``.harmonic_table()``) or an engine :class:`~hbgear.engine.response.PeriodicSolution`;
    ``.multipliers`` either way.

    **Raises:** :class:`~hbgear.errors.ConvergenceError` (where, what was tried, the residual).
    """
    if _check_target(target, speed_rpm, parameter, "solve"):
        return _gear.solve(target, rpm_to_rad_s(float(speed_rpm)), harmonics=_harmonics(harmonics), nu=nu,
                           samples=samples, tolerance=tolerance, max_iterations=max_iterations, z0=z0,
                           stability=stability)
    return _engine.solve(target, float(parameter), harmonics=int(harmonics), nu=nu, samples=samples,
                         tolerance=tolerance, max_iterations=max_iterations, z0=z0, stability=stability)


def frequency_response(target, *, speed_rpm: tuple | None = None, parameter: tuple | None = None, harmonics=24,
                       nu: int = 1, samples: int | None = None, tolerance: float = 1e-9, max_iterations: int = 50,
                       max_points: int = 4000, step: float | None = None, stability: bool = True,
                       period_doubling="auto", progress=None, z0=None):
    """A frequency-response curve by arclength continuation (through folds), with the Floquet
    multipliers of every point, unstable zones of linear models, period doublings located and,
    where bounded, their ``nu = 2`` branches followed.

    **Arguments:** `target` and the range: a gear-pair model with ``speed_rpm=(start, stop)``
    [rpm], or a :class:`~hbgear.engine.system.PeriodicSystem` with ``parameter=(start, stop)``
    (either end may be the larger); `harmonics`, `nu`, `samples`, `tolerance`, `max_iterations`
    as for :func:`solve`; `max_points`; `step`: first step (rpm for the gear pair); `stability`;
    `period_doubling`: ``"auto"`` (gear pair: follow the ``nu = 2`` branches where backlash bounds
    them and they are cheap; a system: locate only), ``True`` (follow), ``False`` (off);
    `progress`: progress bars (``None``: only on a terminal); `z0`: start unknowns (systems).

    **Returns:** a :class:`FrequencyResponse` (gear pair: arrays ``speed_rpm, dte_rms_um,
    dte_p2p_um, stable, nu, ...`` in path order, ``folds``, ``period_doublings``,
    ``unstable_zones``, ``rows()``, ``plot()``) or a :class:`SystemFrequencyResponse`
    (``parameter, coefficients, stable, folds, max_abs(i), plot()``). A continuation that stops
    early is returned with ``success`` False and its message.
    """
    if _check_target(target, speed_rpm, parameter, "frequency_response"):
        start, stop = (float(v) for v in speed_rpm)
        curve = _gear.frequency_response(
            target, rpm_to_rad_s(start), rpm_to_rad_s(stop), harmonics=_harmonics(harmonics), nu=nu, samples=samples,
            tolerance=tolerance, max_iterations=max_iterations, max_points=max_points,
            step=None if step is None else rpm_to_rad_s(float(step)), stability=stability,
            period_doubling=period_doubling, progress=progress, speed_rpm_range=(start, stop))
        return FrequencyResponse(**{f: getattr(curve, f) for f in curve.__dataclass_fields__})
    pd = {"auto": "locate", True: "follow", False: False}.get(period_doubling, period_doubling)
    curve = _engine.frequency_response(
        target, tuple(float(v) for v in parameter), harmonics=int(harmonics), nu=nu, samples=samples,
        tolerance=tolerance, max_iterations=max_iterations, max_points=max_points, step=step, z0=z0,
        stability=stability, period_doubling=pd, progress=progress)
    return SystemFrequencyResponse(**{f: getattr(curve, f) for f in curve.__dataclass_fields__})


def frc_curve(config, *, stability: bool = True, period_doubling=None, progress=None) -> FrequencyResponse:
    """The curve ``hbgear frc`` computes for a validated config: :func:`frequency_response` of its
    model over ``[sweep]`` (range, ``max_points``, ``step_rpm``) with the ``[solver]`` settings
    (``harmonics = "auto"`` honoured); `period_doubling` ``None``: ``sweep.period_doubling``.
    """
    from .build import build_model

    so, sw = config.solver, config.sweep
    flag = sw.period_doubling if period_doubling is None else period_doubling
    return frequency_response(
        build_model(config), speed_rpm=(sw.speed_rpm_start, sw.speed_rpm_stop),
        harmonics=so.harmonics if so.harmonics is not None else "auto", nu=so.subharmonic, samples=so.time_samples,
        tolerance=so.tolerance, max_iterations=so.max_iterations, max_points=sw.max_points, step=sw.step_rpm,
        stability=stability, period_doubling=flag, progress=progress)


def simulate(model: GearPairModel, *, speed_rpm: float, cycles: int = 400, rtol: float = 1e-9, atol_um=None,
             steady_tolerance: float = 1e-6, initial_state=None, progress: bool = False):
    """Time integration of the gear pair to steady state (an independent check of harmonic balance).

    **Arguments:** `speed_rpm` [rpm]; `cycles`: at most this many mesh cycles; `rtol`; `atol_um`
    [um] on displacements (default `rtol` times the static deflection); `steady_tolerance`: change
    of the DTE between periods, relative to its peak-to-peak, that counts as steady;
    `initial_state` ``(q, q')`` (default: the static state).

    **Returns:** a :class:`~hbgear.gear.simulate.TimeResponse` (``.summary``: the read-outs of
    ``summary.json``).

    **Raises:** :class:`~hbgear.errors.ConvergenceError` when no steady state is reached.
    """
    from .gear.simulate import simulate as _simulate

    atol = None if atol_um is None else float(atol_um) * 1e-6
    return _simulate(model, rpm_to_rad_s(float(speed_rpm)), max_cycles=int(cycles), rtol=rtol, atol=atol,
                     steady_tolerance=steady_tolerance, initial_state=initial_state, progress=progress)


def stability_map(config, speeds_rpm, contact_ratios=None) -> np.ndarray:
    """``max |Floquet multiplier|`` per mesh period over contact ratio x speed for the model of
    `config` (one model per contact ratio, ``k_max``/``k_min`` held, ``k_mean`` following):
    exact monodromy for linear models, harmonic balance + Hill otherwise (``[solver]`` settings).

    **Returns:** array ``(len(contact_ratios), len(speeds_rpm))`` (one row without ratios).
    """
    from .build import build_model, model_at_contact_ratio
    from .gear.maps import stability_map as _map

    models = ([build_model(config)] if contact_ratios is None
              else [model_at_contact_ratio(config, g) for g in contact_ratios])
    so = config.solver
    return _map(models, speeds_rpm, harmonics=int(so.harmonics if so.harmonics is not None else 24),
                nu=int(so.subharmonic), samples=int(so.time_samples))

