r"""Time integration of the gear pair to a periodic steady state: the reference for harmonic balance.

The equations are those of :class:`~hbgear.model.GearPairModel`, ``M q'' = Q(s, q, q')`` with
the mesh phase ``s = (t mod T_m)/T_m`` (``t = 0`` at a pair's entry), written as the first-order
system ``y = (q, q')``, ``y' = (q', M^{-1} Q)``.

**Piecewise integration.** ``Q`` jumps at the phases of :meth:`GearPairModel.phase_breakpoints`
(pair entry, pair exit: ``k(t)`` and the load shares; pitch crossings: nominal ``sgn(V_s)``). Every
mesh period is integrated segment by segment between these instants with
:func:`scipy.integrate.solve_ivp`, restarting the integrator at each one, so no step ever
straddles a discontinuity. Inside a segment the phase handed to the model is clamped to the
*open* segment, so rounding at a segment edge never evaluates the neighbouring branch. For the
LTI coupling the loaded static transmission error ``N/k(t)`` jumps with ``k``: its damping term
``c d_st'`` is an impulse, applied as the velocity kick ``M dv = c [d_st]``
(:meth:`GearPairModel.lti_damping_impulse`) at each jump.

**Friction regularisation.** For NLTV the friction coefficient depends on the instantaneous
sliding velocity, so a Coulomb (or Kelley--Lemanski) ``sgn(V_s)`` would switch at unknown
instants and make the right-hand side discontinuous in the state. Such laws must arrive
regularised, ``sgn(V_s) -> (2/pi) atan(V_s / v_reg)`` (the harmonic-balance solver uses the same
law, so both routes solve the same equations): :func:`hbgear.build.build_model` does it with
``[friction] regularization_m_per_s``. If a discontinuous law still reaches :func:`simulate`
with the NLTV coupling (a hand-built model) it is regularised here with ``v_reg`` =
:data:`DEFAULT_V_REG`.
For LTI and LTV ``mu`` uses the nominal kinematics, whose sign changes exactly at the pitch
crossings: those are breakpoints, and no regularisation is needed.

**Method.** ``LSODA`` by default, chosen by measurement on the reference pair (NLTV, arctan
law, spring boundary, ``rtol = 1e-9``; wall time per mesh cycle / right-hand-side calls per
cycle on 2 shared cores):

====================  ====================  ====================  =========================
case                  DOP853                LSODA                 Radau (JAX Jacobian)
====================  ====================  ====================  =========================
3000 rpm, v0=1e-3     144 ms / 1211         91 ms / 799           ~10x DOP853
3000 rpm, v0=1e-5     100 ms / 1252         61 ms / 797
200 rpm, v0=1e-3      984 ms / 10253        526 ms / 7033
200 rpm, v0=1e-5      1487 ms / 18961       837 ms / 9253
====================  ====================  ====================  =========================

The mesh mode (~35,000 rad/s) must be resolved anyway, so the step is accuracy-limited and
the implicit Radau loses; LSODA runs its non-stiff Adams mode here (fewer calls than DOP853 at
equal tolerance) and switches to BDF with the JAX Jacobian by itself when a small ``v_reg``
makes the friction near the pitch point stiff (``~ N mu0 / v_reg``). Its RMS DTE agreed with a
``rtol = 1e-12`` reference to 5e-8 (DOP853: 3e-7 worst, Radau: 1e-9).

**Right-hand side.** ``Q`` is evaluated by the model's own ``generalized_force`` under
``jax.numpy`` behind :func:`jax.jit` (about 2.5x cheaper per call than plain numpy on scalars;
the model is a pytree argument, so one compilation serves every model of the same structure).

**Start and steady state.** The integration starts from the quasi-static state,
``delta = delta_s(0^+)``, ``u = 0`` (the soft spring's wind-up ``u_s`` from
:meth:`GearPairModel.static_state` carries the static output torque including the mean friction
torque), zero velocities, so the transient is short. After every mesh period the DTE at fixed
phases (the quadrature nodes) is compared with the previous period and with the one before it,
relative to its peak-to-peak value; the state counts as steady with period 1 (2) mesh cycles
when that change is below `steady_tolerance` in two successive checks. Only the DTE is tested:
the soft output mode of the ``"spring"`` boundary with ``damping_ratio = 0`` never decays.

**Read-outs.** The summary comes from :func:`hbgear.metrics.periodic_summary` over one steady
period, evaluated at composite Gauss--Legendre nodes of the segments between breakpoints (the
dense output of each segment), exactly as harmonic balance reads out its solution.
"""

from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.integrate import solve_ivp

from .errors import ConfigError, ConvergenceError
from .metrics import periodic_summary
from .quadrature import mesh_period_rule

__all__ = ["TimeResponse", "simulate", "DEFAULT_V_REG"]

#: Regularisation speed [m/s] for a discontinuous friction law under the NLTV coupling.
DEFAULT_V_REG = 5e-3  # the config default, [friction] regularization_m_per_s

_METHODS = ("DOP853", "RK45", "LSODA", "Radau", "BDF")


@dataclass(frozen=True)
class TimeResponse:
    """Steady-state time response of :func:`simulate`.

    **Fields:**

    - `speed_rpm`, `omega_pinion` [rpm], [rad/s]; `mesh_period_s` ``T_m`` [s].
    - `t` [s], `s` mesh phase [-], shape ``(n,)``: a uniform grid over the last `record_cycles`
      steady mesh cycles (``t`` measured from the start of the integration).
    - `q`, `qd`: coordinates [m] and velocities [m/s], shape ``(ndof, n)``; ``q[0]`` is the DTE
      ``delta`` (``"spring"``: ``q[1] = u``, about the static wind-up `u_static`).
    - `mesh_force` ``F_mesh`` [N], shape ``(n,)``; `pairs`: dict of per-pair-slot arrays of shape
      ``(PAIR_SLOTS, n)`` from :meth:`GearPairModel.pair_friction` (``normal`` [N], ``mu`` [-],
      ``friction`` [N], ``vs``, ``vr`` [m/s], ``sigma``, ``xi_p``, ``xi_g`` [m]); slot ``k`` is
      the pair that entered ``k`` mesh periods before the current one.
    - `summary`: :func:`~hbgear.metrics.periodic_summary` over one steady period.
    - `period_cycles`: 1, or 2 when period-doubled; `cycles`: mesh cycles integrated;
      `steady_measure`: the DTE change between periods reached (relative to peak-to-peak).
    - `nodes`: ``(s, q, qd, weights)`` at the quadrature nodes of the steady period (weights sum
      to 1) -- what `summary` was computed from.
    - `u_static` [m]; `method`; `elapsed_s` wall time [s]; `friction_law` used (after any
      regularisation).
    """

    speed_rpm: float
    omega_pinion: float
    mesh_period_s: float
    t: np.ndarray
    s: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    mesh_force: np.ndarray
    pairs: dict
    summary: dict
    period_cycles: int
    cycles: int
    steady_measure: float
    nodes: tuple
    u_static: float
    method: str
    elapsed_s: float
    friction_law: Any


# ----------------------------------------------------------------------------- right-hand side


def _make_rhs(model, omega, u_static, minv, backend, with_jacobian):
    """``f(s, y)`` (and its Jacobian in ``y`` or None) for the first-order system."""
    ndof = model.ndof
    if backend == "numpy":

        def rhs_np(s, y):
            force = model.generalized_force(np.float64(s), y[:ndof], y[ndof:], omega, "all", u_static, 0.0, xp=np)
            return np.concatenate([y[ndof:], minv @ force])

        return rhs_np, None

    import jax
    import jax.numpy as jnp

    jax.config.update("jax_enable_x64", True)
    minv_j = jnp.asarray(minv)

    def rhs(s, y):
        force = model.generalized_force(s, y[:ndof], y[ndof:], omega, "all", u_static, 0.0, xp=jnp)
        return jnp.concatenate([y[ndof:], minv_j @ force])

    # the model's constants are closed over: one compilation per call (~0.3 s), then ~30 us
    # per evaluation (a pytree argument would cost ~150 us per call in flattening)
    rhs_jit = jax.jit(rhs)
    jac_jit = jax.jit(jax.jacfwd(rhs, argnums=1)) if with_jacobian else None

    def f(s, y):
        return np.asarray(rhs_jit(s, y))

    def jac(s, y):
        return np.asarray(jac_jit(s, y))

    return f, (jac if with_jacobian else None)


# ----------------------------------------------------------------------------- helpers


def _prepared_model(model):
    """The model with a discontinuous friction law regularised when it sees the state (NLTV)."""
    if model.coupling == "NLTV" and model.friction.discontinuous:
        return model.replace(friction=model.friction.regularized(DEFAULT_V_REG))
    return model


def _initial_state(model, omega, u_static, s0):
    """Quasi-static start at phase ``s0`` (just after a pair's entry), zero velocities."""
    _, _, wm = model.speeds(omega)
    s = np.asarray([s0])
    if model.coupling == "LTI":
        delta = model.normal_load_N / model.k_mean_N_per_m + model.loaded_static_transmission_error(s, wm)[0]
    else:
        eps, _ = model.static_transmission_error(s, wm)
        delta = eps[0] + model.normal_load_N / model.mesh_stiffness(s)[0]
        if model.contact == "backlash":
            delta = delta + 0.5 * model.backlash_m
    y0 = np.zeros(2 * model.ndof)
    y0[0] = float(delta)
    return y0


def _segment_plan(breakpoints, node_s, grid_s):
    """Per segment ``(a, b, node indices, grid indices)`` for phases in one mesh period."""
    edges = np.concatenate([np.asarray(breakpoints, float), [1.0]])
    plan = []
    for a, b in zip(edges[:-1], edges[1:]):
        if b - a <= 0.0:
            continue
        nodes = np.nonzero((node_s >= a) & (node_s < b))[0]
        grid = np.nonzero((grid_s >= a) & (grid_s < b))[0]
        plan.append((float(a), float(b), nodes, grid))
    return plan


def _steady_period(changes, tolerance, period_cycles):
    """The steady period (1 or 2 mesh cycles) from the last two checks, or None.

    `changes` holds ``(c1, c2)`` for the last two cycles: the largest change of the DTE at fixed
    phases against one and two cycles before, relative to its peak-to-peak. Period 1 needs
    ``c1 < tolerance`` in both. Period 2 needs ``c2 < tolerance`` in both while successive cycles
    still differ clearly (``c1 > max(1e3 tolerance, 1e-4)``) and that difference is not
    shrinking (``c1`` kept above 0.9 of its previous value): a transient decaying with a Floquet
    multiplier near -1 also makes ``c2`` much smaller than ``c1``, but ``c1`` then decays.
    """
    (p1, p2), (n1, n2) = changes
    if 1 in period_cycles and max(p1, n1) < tolerance:
        return 1
    if (
        2 in period_cycles
        and max(p2, n2) < tolerance
        and n1 > max(1e3 * tolerance, 1e-4)
        and n1 > 0.9 * p1
    ):
        return 2
    return None


def _deflate_soft_mode(model, omega, u_static, node_s, node_w, node_y, y_end, tm):
    r"""Remove the free oscillation of the soft output mode from the end-of-cycle state.

    In the periodic steady state ``<u'> = 0`` and, averaging the second row of the equations
    (whose inertia terms average to zero), ``k_u (<u> + u_s) + c_u <u'> = <F_2>`` with
    ``F_2 = T_p/R_bp + T_fp/R_bp + T_fg/R_bg``. The cycle means of ``u`` and ``u'`` minus these
    values estimate the soft mode's displacement and velocity at mid-cycle (its period is many
    mesh cycles); they are propagated half a cycle to the end with the mode's frequency
    ``w_s = sqrt(k_u / (m_p + m_g))`` and subtracted. Only the state is changed, never the
    equations, and a cycle that ends steady is not corrected, so the read-out period is a
    genuine trajectory.
    """
    ndof = model.ndof
    q, qd = node_y[:ndof], node_y[ndof:]
    k_u = float(model.spring_stiffness_N_per_m)
    c_u = float(model.spring_damping_Ns_per_m)
    force = model.generalized_force(node_s, q, qd, omega, "all", u_static, 0.0)
    mean_u = float(np.sum(node_w * q[1]))
    mean_ud = float(np.sum(node_w * qd[1]))
    mean_f2 = float(np.sum(node_w * force[1])) + k_u * (mean_u + u_static) + c_u * mean_ud
    target_u = mean_f2 / k_u - u_static
    du, dv = mean_u - target_u, mean_ud
    ws2 = k_u / float(model.mass_pinion_kg + model.mass_gear_kg)
    half = 0.5 * tm
    y = y_end.copy()
    y[1] -= du + dv * half
    y[ndof + 1] -= dv - ws2 * du * half
    return y


# ----------------------------------------------------------------------------- driver


def simulate(
    model,
    omega_pinion: float,
    *,
    max_cycles: int = 400,
    rtol: float = 1e-9,
    atol: float | None = None,
    steady_tolerance: float = 1e-6,
    period_cycles: tuple[int, ...] = (1, 2),
    record_cycles: int = 2,
    progress: bool = False,
    method: str = "LSODA",
    backend: str = "jax",
    samples_per_cycle: int | None = None,
    deflate_soft_mode: bool = True,
    initial_state=None,
) -> TimeResponse:
    r"""Integrate the gear pair from its static state until the DTE is periodic.

    **Arguments:**

    - `model`: a :class:`~hbgear.model.GearPairModel` with boundary ``"torques"`` or
      ``"spring"``; `omega_pinion`: ``Omega_p`` [rad/s].
    - `max_cycles`: at most this many mesh periods are integrated.
    - `rtol`, `atol`: integrator tolerances; `atol` [m] applies to the displacements (default
      ``rtol`` times the static deflection ``N/k_mean``), velocities get ``atol w_n``.
    - `steady_tolerance`: largest change of the DTE at fixed phases between periods, relative to
      its peak-to-peak, that counts as steady [-].
    - `period_cycles`: periods (in mesh cycles) to look for: ``(1,)`` or ``(1, 2)``.
    - `record_cycles`: steady mesh cycles kept on the uniform grid (raised to the period).
    - `progress`: show a tqdm bar over the cycles.
    - `method`: a :func:`scipy.integrate.solve_ivp` method (see the module docstring).
    - `backend`: ``"jax"`` (jit-compiled right-hand side) or ``"numpy"``.
    - `samples_per_cycle`: uniform grid points per mesh cycle (default: enough for the mesh mode).
    - `deflate_soft_mode`: (``"spring"`` only) remove the soft output mode's free oscillation at
      the end of every unsteady cycle (see :func:`_deflate_soft_mode`); it barely decays
      (period ~0.26 s for the reference pair, hundreds of mesh cycles) and, although it hardly
      shows in the DTE, its kinetic-energy exchange at the nominal speeds spoils the power
      balance of any single period.
    - `initial_state`: ``(q, q')`` flattened, shape ``(2 ndof,)`` [m, m/s], at mesh phase 0
      (e.g. the last state of a neighbouring speed, for up/down sweeps); default: the
      quasi-static state.

    **Returns:** a :class:`TimeResponse`.

    **Raises:** :class:`~hbgear.errors.ConfigError` for a ``"reaction"`` boundary (its mean
    output torque is fixed by periodicity, which a marching scheme cannot impose) or bad
    options; :class:`~hbgear.errors.ConvergenceError` when no steady state is reached within
    `max_cycles` (the message gives the speed, the cycles tried and the change reached).
    """
    start_time = time.perf_counter()
    if model.boundary == "reaction":
        raise ConfigError(
            "boundary.output", "reaction", "'torques' or 'spring' for time integration (simulate)"
        )
    if method not in _METHODS:
        raise ConfigError("method", method, f"one of {_METHODS}")
    if backend not in ("jax", "numpy"):
        raise ConfigError("backend", backend, "'jax' or 'numpy'")
    period_cycles = tuple(sorted(set(int(p) for p in period_cycles)))
    if not period_cycles or not set(period_cycles) <= {1, 2}:
        raise ConfigError("period_cycles", period_cycles, "a subset of (1, 2)")
    if max_cycles < 2:
        raise ConfigError("max_cycles", max_cycles, "an integer >= 2")

    model = _prepared_model(model)
    omega = float(omega_pinion)
    _, _, wm = model.speeds(omega)
    tm = 2.0 * math.pi / wm
    ndof = model.ndof
    mass = np.asarray(model.mass_matrix(), dtype=float)
    minv = np.linalg.inv(mass)
    _, u_static = model.static_state(omega)
    u_static = float(u_static)

    k_mean = float(model.k_mean_N_per_m)
    wn = math.sqrt(k_mean / float(model.mass_equivalent_kg))
    ratio = wn / wm  # mesh-mode oscillations per mesh period
    if atol is None:
        atol = rtol * float(model.normal_load_N) / k_mean
    atol_vec = np.concatenate([np.full(ndof, atol), np.full(ndof, atol * wn)])

    # quadrature nodes (read-outs, steady test) and the uniform recording grid, per period
    breakpoints = np.asarray(model.phase_breakpoints(), dtype=float)
    max_order = int(min(2000, max(48, math.ceil(4.0 * ratio))))
    node_s, node_w = mesh_period_rule(breakpoints[breakpoints > 0.0], max_order)
    node_s, node_w = np.asarray(node_s), np.asarray(node_w)
    keep_nodes = node_w > 0.0
    node_s, node_w = node_s[keep_nodes], node_w[keep_nodes]
    if np.any(np.diff(node_s) <= 0.0):
        order = np.argsort(node_s)
        node_s, node_w = node_s[order], node_w[order]
    if samples_per_cycle is None:
        samples_per_cycle = int(max(256, 2 ** math.ceil(math.log2(24.0 * ratio))))
    grid_s = np.arange(samples_per_cycle) / samples_per_cycle
    plan = _segment_plan(breakpoints, node_s, grid_s)
    kicks = [model.lti_damping_impulse(a, omega) for a, _, _, _ in plan]
    kick_dv = [minv @ k if np.any(k) else None for k in kicks]

    implicit = method in ("Radau", "BDF", "LSODA")
    deflate = deflate_soft_mode and model.boundary == "spring"
    rhs, jac = _make_rhs(model, omega, u_static, minv, backend, implicit)
    if initial_state is None:
        y = _initial_state(model, omega, u_static, plan[0][0] + 1e-12)
    else:
        y = np.asarray(initial_state, dtype=float).reshape(2 * model.ndof).copy()
    keep = max(record_cycles, max(period_cycles), 3)
    history: deque = deque(maxlen=keep)  # (cycle, node_y, grid_y, kick_work)
    changes: deque = deque(maxlen=2)  # per-cycle (change1, change2)
    nfev = 0
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=max_cycles, desc=f"simulate {omega * 30 / math.pi:.6g} rpm", unit="cycle")

    found_period = None
    measure = math.inf
    cycle = 0
    for cycle in range(max_cycles):
        t_cycle = cycle * tm
        node_y = np.empty((2 * ndof, node_s.size))
        grid_y = np.empty((2 * ndof, grid_s.size))
        kick_work = 0.0  # work of the LTI impulses on the DTE, J (v- + v+)/2, over this cycle
        for (a, b, nodes, grid), dv, impulse in zip(plan, kick_dv, kicks):
            if dv is not None:
                y = y.copy()
                kick_work += float(impulse[0]) * (2 * y[ndof] + dv[0]) / 2
                y[ndof:] += dv
            width = b - a
            margin = 1e-12 * max(width, 1e-3)
            lo, hi = a + margin, b - margin
            t0, t1 = t_cycle + a * tm, t_cycle + b * tm

            def fun(t, yy, t0=t0, lo=lo, hi=hi, a=a):
                return rhs(min(max(a + (t - t0) / tm, lo), hi), yy)

            if jac is not None and implicit:

                def jfun(t, yy, t0=t0, lo=lo, hi=hi, a=a):
                    return jac(min(max(a + (t - t0) / tm, lo), hi), yy)

                extra = {"jac": jfun}
            else:
                extra = {}
            t_eval = np.concatenate([t_cycle + node_s[nodes] * tm, t_cycle + grid_s[grid] * tm, [t1]])
            order = np.argsort(t_eval, kind="stable")
            sol = solve_ivp(
                fun, (t0, t1), y, method=method, t_eval=t_eval[order], rtol=rtol, atol=atol_vec, **extra
            )
            if not sol.success:
                raise ConvergenceError(
                    f"time integration at {omega * 30 / math.pi:.6g} rpm failed in mesh cycle {cycle} "
                    f"(phase {a:.4f}..{b:.4f}): {sol.message}; try method='Radau' or looser tolerances"
                )
            nfev += sol.nfev
            values = np.empty_like(sol.y)
            values[:, order] = sol.y
            node_y[:, nodes] = values[:, : nodes.size]
            grid_y[:, grid] = values[:, nodes.size : nodes.size + grid.size]
            y = values[:, -1].copy()
        history.append((cycle, node_y, grid_y, kick_work))
        if bar is not None:
            bar.update(1)

        # steady-state test on the DTE only
        delta = node_y[0]
        scale = max(float(np.ptp(delta)), 1e-12 * float(np.max(np.abs(delta))), 1e-300)
        c1 = c2 = math.inf
        if len(history) >= 2:
            c1 = float(np.max(np.abs(delta - history[-2][1][0]))) / scale
        if len(history) >= 3:
            c2 = float(np.max(np.abs(delta - history[-3][1][0]))) / scale
        changes.append((c1, c2))
        if bar is not None:
            bar.set_postfix(change=f"{min(c1, c2):.2e}")
        if len(changes) == 2:
            found_period = _steady_period(list(changes), steady_tolerance, period_cycles)
            if found_period is not None:
                measure = max(c[found_period - 1] for c in changes)
        if found_period is not None:
            break
        measure = c1 if 2 not in period_cycles else min(c1, c2)
        if deflate:
            y = _deflate_soft_mode(model, omega, u_static, node_s, node_w, node_y, y, tm)
    if bar is not None:
        bar.close()
    cycles_done = cycle + 1
    if found_period is None:
        raise ConvergenceError(
            f"time integration at {omega * 30 / math.pi:.6g} rpm reached no steady state within "
            f"{cycles_done} mesh cycles: the DTE still changes by {measure:.2e} of its peak-to-peak "
            f"between periods (tolerance {steady_tolerance:.1e}); raise the mesh damping ratio or "
            f"[boundary] damping_ratio, or allow more cycles (--cycles / simulate.cycles)"
        )

    # one steady period at the quadrature nodes -> summary (weights sum to 1)
    steady = list(history)[-found_period:]
    s_nodes = np.concatenate([node_s] * found_period)
    w_nodes = np.concatenate([node_w / found_period] * found_period)
    ys = np.concatenate([h[1] for h in steady], axis=1)
    q_nodes, qd_nodes = ys[:ndof], ys[ndof:]
    summary = {k: float(v) for k, v in periodic_summary(model, omega, s_nodes, q_nodes, qd_nodes, w_nodes, u_static).items()}
    # LTI: the impulses c [d_st] of -F_mesh at the stiffness jumps do work on the DTE that the
    # quadrature over the smooth segments does not see; <F delta'> includes it
    summary["mean_mesh_power_W"] -= sum(h[3] for h in steady) / (found_period * tm)

    # the recorded cycles on the uniform grid
    n_rec = min(len(history), max(record_cycles, found_period))
    rec = list(history)[-n_rec:]
    t_rec = np.concatenate([(h[0] + grid_s) * tm for h in rec])
    s_rec = np.concatenate([grid_s] * n_rec)
    y_rec = np.concatenate([h[2] for h in rec], axis=1)
    q_rec, qd_rec = y_rec[:ndof], y_rec[ndof:]
    mesh = np.asarray(model.mesh_force(s_rec, q_rec, qd_rec, omega))
    pairs = {k: np.asarray(v) for k, v in model.pair_friction(s_rec, q_rec, qd_rec, omega).items()}
    return TimeResponse(
        speed_rpm=omega * 30.0 / math.pi,
        omega_pinion=omega,
        mesh_period_s=tm,
        t=t_rec,
        s=s_rec,
        q=q_rec,
        qd=qd_rec,
        mesh_force=mesh,
        pairs=pairs,
        summary=summary,
        period_cycles=found_period,
        cycles=cycles_done,
        steady_measure=measure,
        nodes=(s_nodes, q_nodes, qd_nodes, w_nodes),
        u_static=u_static,
        method=method,
        elapsed_s=time.perf_counter() - start_time,
        friction_law=model.friction,
    )
