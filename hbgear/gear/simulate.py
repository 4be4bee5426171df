r"""Time integration of the gear pair to a periodic steady state: the reference for harmonic balance.

The equations are those of :class:`~hbgear.gear.model.GearPairModel`, ``M q'' = Q(s, q, q')`` with
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
when that change is below `steady_tolerance` in two successive checks. Only the DTE is tested
(and ``u'`` for ``"reaction"``): the soft output mode of the ``"spring"`` boundary with
``damping_ratio = 0`` never decays.

**Reaction boundary.** The free output inertia carries a constant output torque ``T_g = R_bg R``
whose value periodicity fixes, ``R = <F_2>`` (the mean of the second equation's right-hand side
without it). Marching cannot impose periodicity, so ``R`` is updated between cycles to the last
cycle's ``<F_2>`` and the rigid-body drift it caused is taken out of ``u`` and ``u'``
(:func:`_reaction_update`, started from the quasi-static ``R``). Corrections stop once the DTE
and ``u'`` are steady, so the read-out period integrates the equations with one constant
``R`` -- the harmonic-balance solution (mean ``u`` pinned to 0).

**Fixed-length runs.** :func:`march` integrates a given number of cycles with the same
machinery (:class:`_Integrator`) and no steady-state test, keeping per-cycle read-outs and the
Poincare samples (unstable zones, transients, paper Figs. 12 and 14).

**Read-outs.** The summary comes from :func:`hbgear.gear.readouts.periodic_summary` over one steady
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

from ..errors import ConvergenceError
from .readouts import periodic_summary
from ..engine.quadrature import mesh_period_rule

__all__ = ["TimeResponse", "MarchRecord", "simulate", "march", "DEFAULT_V_REG"]

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
    - `summary`: :func:`~hbgear.gear.readouts.periodic_summary` over one steady period.
    - `period_cycles`: 1, or 2 when period-doubled; `cycles`: mesh cycles integrated;
      `steady_measure`: the DTE change between periods reached (relative to peak-to-peak).
    - `nodes`: ``(s, q, qd, weights)`` at the quadrature nodes of the steady period (weights sum
      to 1) -- what `summary` was computed from.
    - `u_static` [m]; `method`; `elapsed_s` wall time [s]; `friction_law` used (after any
      regularisation); `reaction_force_N`: the output force ``T_g/R_bg`` [N] of the steady
      period (``"reaction"``; 0 otherwise).
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
    reaction_force_N: float = 0.0


# ----------------------------------------------------------------------------- right-hand side


def _make_rhs(model, omega, u_static, minv, backend, with_jacobian):
    """``f(s, y, reaction)`` (and its Jacobian in ``y`` or None) for the first-order system.

    `reaction` is the output force ``T_g/R_bg`` [N] of the ``"reaction"`` boundary (0 otherwise),
    a traced argument: changing it between mesh cycles does not recompile.
    """
    ndof = model.ndof
    if backend == "numpy":

        def rhs_np(s, y, reaction):
            force = model.generalized_force(np.float64(s), y[:ndof], y[ndof:], omega, "all", u_static, reaction, xp=np)
            return np.concatenate([y[ndof:], minv @ force])

        return rhs_np, None

    import jax
    import jax.numpy as jnp

    jax.config.update("jax_enable_x64", True)
    minv_j = jax.device_put(np.asarray(minv))  # not jnp.asarray: no compiled program for the copy

    def rhs(s, y, reaction):
        force = model.generalized_force(s, y[:ndof], y[ndof:], omega, "all", u_static, reaction, xp=jnp)
        return jnp.concatenate([y[ndof:], minv_j @ force])

    # the model's constants are closed over: one compilation per call (~0.3 s), then ~30 us
    # per evaluation (a pytree argument would cost ~150 us per call in flattening)
    rhs_jit = jax.jit(rhs)
    jac_jit = jax.jit(jax.jacfwd(rhs, argnums=1)) if with_jacobian else None

    def f(s, y, reaction):
        return np.asarray(rhs_jit(s, y, reaction))

    def jac(s, y, reaction):
        return np.asarray(jac_jit(s, y, reaction))

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
        delta = model.static_dte(s, omega)[0]
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
    ``w_s = sqrt(k_u / M_uu)`` (``M_uu = m_p + m_g`` without shafts) and subtracted. Only the state is changed, never the
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
    ws2 = k_u / float(model.rigid_mass_kg)
    half = 0.5 * tm
    y = y_end.copy()
    y[1] -= du + dv * half
    y[ndof + 1] -= dv - ws2 * du * half
    return y


def _output_force_mean(model, omega, node_s, node_w, node_y):
    """``<F_2> = <T_p/R_bp + T_fp/R_bp + T_fg/R_bg>`` [N] over a cycle (``"reaction"``, no spring)."""
    ndof = model.ndof
    force = model.generalized_force(node_s, node_y[:ndof], node_y[ndof:], omega, "all", 0.0, 0.0)
    return float(np.sum(node_w * force[1]))


def _reaction_update(model, omega, node_s, node_w, node_y, y_end, reaction, tm):
    r"""Output force and start state of the next cycle for the ``"reaction"`` boundary.

    The output force ``R = T_g/R_bg`` is the unknown that periodicity fixes: averaging the
    momentum equation ``(m_p delta' + (m_p + m_g) u')' = F_2 - R`` over a period gives
    ``R = <F_2>``. The next cycle gets ``R`` from this cycle's ``<F_2>``, and the free rigid-body
    motion is removed from the end state: ``u'`` by its cycle mean plus the half-cycle drift
    ``T_m (<F_2> - R) / (2 (m_p + m_g))`` that a mismatched ``R`` caused, ``u`` by its cycle mean
    (nothing depends on ``u`` itself). At the fixed point both corrections vanish and ``R`` is
    constant, so a steady cycle (which is not corrected) is a genuine periodic trajectory of the
    equations with a constant output torque -- the harmonic-balance solution with its mean
    ``u`` pinned to zero.
    """
    ndof = model.ndof
    mean_f2 = _output_force_mean(model, omega, node_s, node_w, node_y)
    drift = tm * (mean_f2 - reaction) / float(model.rigid_mass_kg)
    y = y_end.copy()
    y[1] -= float(np.sum(node_w * node_y[1]))
    y[ndof + 1] -= float(np.sum(node_w * node_y[ndof + 1])) + 0.5 * drift
    return y, mean_f2


def _initial_reaction(model, omega):
    """Output force [N] of the quasi-static state: ``<F_2>`` with zero velocities (``"reaction"``)."""
    if model.boundary != "reaction":
        return 0.0
    from ..engine.quadrature import mesh_period_rule

    s, w = mesh_period_rule(model.breakpoint_candidates(), 4, same_nodes=True)  # static_state's nodes
    delta, _ = model.static_state(omega)
    q = np.stack([np.asarray(delta)] + [0.0 * np.asarray(s)] * (model.ndof - 1))
    return _output_force_mean(model, omega, np.asarray(s), np.asarray(w), np.concatenate([q, 0.0 * q]))


# ----------------------------------------------------------------------------- one mesh cycle


@dataclass(frozen=True)
class _Cycle:
    """One integrated mesh cycle: the state at the quadrature nodes and on the uniform grid,
    ``(2 ndof, n)``, the work of the LTI impulses, the end state, the output force used."""

    index: int
    node_y: np.ndarray
    grid_y: np.ndarray
    kick_work: float
    y_end: np.ndarray
    reaction: float
    nfev: int


class _Integrator:
    """The piecewise integration of one mesh period (module docstring), set up once per speed.

    Holds the prepared model, the quadrature nodes (read-outs, steady-state test), the uniform
    recording grid, the segment plan with the LTI impulses and the compiled right-hand side.
    :meth:`run_cycle` integrates one cycle and :meth:`next_start` prepares the next;
    :func:`simulate` and :func:`march` differ only in when they stop.
    """

    def __init__(self, model, omega, *, rtol, atol, method, backend, samples_per_cycle, deflate_soft_mode):
        if method not in _METHODS:
            raise ValueError(f"method = {method!r}: one of {_METHODS}")
        if backend not in ("jax", "numpy"):
            raise ValueError(f"backend = {backend!r}: 'jax' or 'numpy'")
        model = _prepared_model(model)
        self.model = model
        self.omega = omega = float(omega)
        _, _, wm = model.speeds(omega)
        self.tm = 2.0 * math.pi / wm
        self.ndof = ndof = model.ndof
        self.minv = minv = np.linalg.inv(np.asarray(model.mass_matrix(), dtype=float))
        self.u_static = float(model.static_windup(omega))

        k_mean = float(model.k_mean_N_per_m)
        wn = math.sqrt(k_mean / float(model.mass_equivalent_kg))
        ratio = wn / wm  # mesh-mode oscillations per mesh period
        if atol is None:
            atol = rtol * float(model.normal_load_N) / k_mean
        self.rtol = rtol
        self.atol_vec = np.concatenate([np.full(ndof, atol), np.full(ndof, atol * wn)])
        self.method = method

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
        self.node_s, self.node_w = node_s, node_w
        if samples_per_cycle is None:
            samples_per_cycle = int(max(256, 2 ** math.ceil(math.log2(24.0 * ratio))))
        self.grid_s = np.arange(samples_per_cycle) / samples_per_cycle
        self.plan = _segment_plan(breakpoints, node_s, self.grid_s)
        if model.coupling == "LTI" and not model.mesh.equal_shares:
            raise ValueError("time integration of LTI applies c dD/dt of the loaded static TE as kicks at its jumps "
                             "only: a per-pair mesh whose static deflection D(s) varies between them needs LTV or NLTV")
        self.kicks = [model.lti_damping_impulse(a, omega) for a, _, _, _ in self.plan]
        self.kick_dv = [minv @ k if np.any(k) else None for k in self.kicks]

        self.implicit = method in ("Radau", "BDF", "LSODA")
        self.deflate = deflate_soft_mode and model.boundary == "spring"
        self.rhs, self.jac = _make_rhs(model, omega, self.u_static, minv, backend, self.implicit)

    def start_state(self, initial_state):
        """The given ``(q, q')`` at phase 0, or the quasi-static start."""
        if initial_state is None:
            return _initial_state(self.model, self.omega, self.u_static, self.plan[0][0] + 1e-12)
        return np.asarray(initial_state, dtype=float).reshape(2 * self.ndof).copy()

    def run_cycle(self, y, cycle: int, reaction: float) -> _Cycle:
        """Integrate mesh cycle number `cycle` (``t = cycle T_m`` at its start) from state `y`."""
        tm, ndof, node_s, grid_s = self.tm, self.ndof, self.node_s, self.grid_s
        rhs, jac, method = self.rhs, self.jac, self.method
        t_cycle = cycle * tm
        node_y = np.empty((2 * ndof, node_s.size))
        grid_y = np.empty((2 * ndof, grid_s.size))
        kick_work = 0.0  # work of the LTI impulses on the DTE, J (v- + v+)/2, over this cycle
        nfev = 0
        for (a, b, nodes, grid), dv, impulse in zip(self.plan, self.kick_dv, self.kicks):
            if dv is not None:
                y = y.copy()
                kick_work += float(impulse[0]) * (2 * y[ndof] + dv[0]) / 2
                y[ndof:] += dv
            width = b - a
            margin = 1e-12 * max(width, 1e-3)
            lo, hi = a + margin, b - margin
            t0, t1 = t_cycle + a * tm, t_cycle + b * tm

            def fun(t, yy, t0=t0, lo=lo, hi=hi, a=a):
                return rhs(min(max(a + (t - t0) / tm, lo), hi), yy, reaction)

            if jac is not None and self.implicit:

                def jfun(t, yy, t0=t0, lo=lo, hi=hi, a=a):
                    return jac(min(max(a + (t - t0) / tm, lo), hi), yy, reaction)

                extra = {"jac": jfun}
            else:
                extra = {}
            t_eval = np.concatenate([t_cycle + node_s[nodes] * tm, t_cycle + grid_s[grid] * tm, [t1]])
            order = np.argsort(t_eval, kind="stable")
            sol = solve_ivp(
                fun, (t0, t1), y, method=method, t_eval=t_eval[order], rtol=self.rtol, atol=self.atol_vec, **extra
            )
            if not sol.success:
                raise ConvergenceError(
                    f"time integration at {self.omega * 30 / math.pi:.6g} rpm failed in mesh cycle {cycle} "
                    f"(phase {a:.4f}..{b:.4f}): {sol.message}; try method='Radau' or looser tolerances"
                )
            nfev += sol.nfev
            values = np.empty_like(sol.y)
            values[:, order] = sol.y
            node_y[:, nodes] = values[:, : nodes.size]
            grid_y[:, grid] = values[:, nodes.size : nodes.size + grid.size]
            y = values[:, -1].copy()
        return _Cycle(cycle, node_y, grid_y, kick_work, y, float(reaction), nfev)

    def next_start(self, done: _Cycle):
        """``(state, output force)`` to start the cycle after `done`: the soft-mode deflation
        (``"spring"``, when enabled) or the reaction update (``"reaction"``) applied to its end."""
        if self.deflate:
            y = _deflate_soft_mode(self.model, self.omega, self.u_static, self.node_s, self.node_w,
                                   done.node_y, done.y_end, self.tm)
            return y, done.reaction
        if self.model.boundary == "reaction":
            return _reaction_update(self.model, self.omega, self.node_s, self.node_w, done.node_y, done.y_end,
                                    done.reaction, self.tm)
        return done.y_end, done.reaction

    def tested_rows(self):
        """State rows of the steady-state test: the DTE, and ``u'`` for the reaction boundary
        (its rigid-body velocity must also have settled)."""
        return (0, self.ndof + 1) if self.model.boundary == "reaction" else (0,)


def _relative_change(now, before):
    """Largest change at fixed phases relative to the peak-to-peak, over the tested rows."""
    worst = 0.0
    for a, b in zip(now, before):
        scale = max(float(np.ptp(a)), 1e-12 * float(np.max(np.abs(a))), 1e-300)
        worst = max(worst, float(np.max(np.abs(a - b))) / scale)
    return worst


# ----------------------------------------------------------------------------- drivers


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

    - `model`: a :class:`~hbgear.gear.model.GearPairModel` (any boundary); `omega_pinion`:
      ``Omega_p`` [rad/s].
    - `max_cycles`: at most this many mesh periods are integrated.
    - `rtol`, `atol`: integrator tolerances; `atol` [m] applies to the displacements (default
      ``rtol`` times the static deflection ``N/k_mean``), velocities get ``atol w_n``.
    - `steady_tolerance`: largest change of the DTE at fixed phases between periods, relative to
      its peak-to-peak, that counts as steady [-] (``"reaction"``: the same for ``u'``).
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

    With the ``"reaction"`` boundary the output force is updated after every unsteady cycle to
    that cycle's mean ``<F_2>`` and the rigid-body drift of ``u`` is removed
    (:func:`_reaction_update`); the force of the steady period is `reaction_force_N`.

    **Returns:** a :class:`TimeResponse`.

    **Raises:** ``ValueError`` for bad options;
    :class:`~hbgear.errors.ConvergenceError` when no steady state is reached within
    `max_cycles` (the message gives the speed, the cycles tried and the change reached).
    """
    start_time = time.perf_counter()
    period_cycles = tuple(sorted(set(int(p) for p in period_cycles)))
    if not period_cycles or not set(period_cycles) <= {1, 2}:
        raise ValueError(f"period_cycles = {period_cycles!r}: a subset of (1, 2)")
    if max_cycles < 2:
        raise ValueError(f"max_cycles = {max_cycles!r}: an integer >= 2")
    run = _Integrator(model, omega_pinion, rtol=rtol, atol=atol, method=method, backend=backend,
                      samples_per_cycle=samples_per_cycle, deflate_soft_mode=deflate_soft_mode)
    history, found_period, measure = _until_steady(run, initial_state, max_cycles, steady_tolerance, period_cycles,
                                                   max(record_cycles, max(period_cycles), 3), progress)
    steady = list(history)[-found_period:]
    nodes, summary = _steady_summary(run, steady)
    t_rec, s_rec, q_rec, qd_rec = _recorded(run, list(history)[-min(len(history), max(record_cycles, found_period)):])
    model, omega = run.model, run.omega
    return TimeResponse(
        speed_rpm=omega * 30.0 / math.pi,
        omega_pinion=omega,
        mesh_period_s=run.tm,
        t=t_rec,
        s=s_rec,
        q=q_rec,
        qd=qd_rec,
        mesh_force=np.asarray(model.mesh_force(s_rec, q_rec, qd_rec, omega)),
        pairs={k: np.asarray(v) for k, v in model.pair_friction(s_rec, q_rec, qd_rec, omega).items()},
        summary=summary,
        period_cycles=found_period,
        cycles=history[-1].index + 1,
        steady_measure=measure,
        nodes=nodes,
        u_static=run.u_static,
        method=method,
        elapsed_s=time.perf_counter() - start_time,
        friction_law=model.friction,
        reaction_force_N=steady[-1].reaction,
    )


def _until_steady(run, initial_state, max_cycles, steady_tolerance, period_cycles, keep, progress):
    """Integrate cycle after cycle until the tested rows repeat with a period of `period_cycles`
    (:func:`_steady_period` on the last two cycles' changes). **Returns:** ``(history of the last
    `keep` cycles, the period found, the change measured)``. **Raises:** ConvergenceError after
    `max_cycles` without one."""
    rows = list(run.tested_rows())
    history: deque[_Cycle] = deque(maxlen=keep)
    changes: deque = deque(maxlen=2)  # per-cycle (change1, change2)
    bar = _cycle_bar(progress, max_cycles, run.omega)
    found_period, measure = None, math.inf
    y, reaction = run.start_state(initial_state), _initial_reaction(run.model, run.omega)
    for cycle in range(max_cycles):
        done = run.run_cycle(y, cycle, reaction)
        history.append(done)
        tested = done.node_y[rows]
        c1 = _relative_change(tested, history[-2].node_y[rows]) if len(history) >= 2 else math.inf
        c2 = _relative_change(tested, history[-3].node_y[rows]) if len(history) >= 3 else math.inf
        changes.append((c1, c2))
        if bar is not None:
            bar.update(1)
            bar.set_postfix(change=f"{min(c1, c2):.2e}")
        if len(changes) == 2:
            found_period = _steady_period(list(changes), steady_tolerance, period_cycles)
            if found_period is not None:
                measure = max(c[found_period - 1] for c in changes)
                break
        measure = c1 if 2 not in period_cycles else min(c1, c2)
        # a cycle that ends steady is never corrected: the read-out period is a genuine trajectory
        y, reaction = run.next_start(done)
    if bar is not None:
        bar.close()
    if found_period is None:
        raise ConvergenceError(
            f"time integration at {run.omega * 30 / math.pi:.6g} rpm reached no steady state within "
            f"{history[-1].index + 1} mesh cycles: the DTE still changes by {measure:.2e} of its peak-to-peak "
            f"between periods (tolerance {steady_tolerance:.1e}); raise the mesh damping ratio or "
            f"the soft output spring's damping ratio, or allow more cycles (max_cycles)"
        )
    return history, found_period, measure


def _cycle_bar(progress, total, omega):
    if not progress:
        return None
    from tqdm import tqdm

    return tqdm(total=total, desc=f"simulate {omega * 30 / math.pi:.6g} rpm", unit="cycle")


def _steady_summary(run, steady):
    """``(nodes, summary)`` of one steady period (the cycles `steady`) at the quadrature nodes:
    :func:`~hbgear.gear.readouts.periodic_summary` (weights sum to 1), the LTI impulses' work on the
    DTE added to ``<F delta'>`` (the quadrature over the smooth segments does not see it)."""
    period, ndof = len(steady), run.ndof
    s_nodes = np.concatenate([run.node_s] * period)
    w_nodes = np.concatenate([run.node_w / period] * period)
    ys = np.concatenate([h.node_y for h in steady], axis=1)
    q_nodes, qd_nodes = ys[:ndof], ys[ndof:]
    summary = {k: float(v) for k, v in periodic_summary(run.model, run.omega, s_nodes, q_nodes, qd_nodes, w_nodes,
                                                         run.u_static, steady[-1].reaction).items()}
    summary["mean_mesh_power_W"] -= sum(h.kick_work for h in steady) / (period * run.tm)
    return (s_nodes, q_nodes, qd_nodes, w_nodes), summary


def _recorded(run, cycles):
    """``(t, s, q, q')`` of the recorded `cycles` on the uniform grid."""
    t_rec = np.concatenate([(h.index + run.grid_s) * run.tm for h in cycles])
    s_rec = np.concatenate([run.grid_s] * len(cycles))
    y_rec = np.concatenate([h.grid_y for h in cycles], axis=1)
    return t_rec, s_rec, y_rec[:run.ndof], y_rec[run.ndof:]


@dataclass(frozen=True)
class MarchRecord:
    """A fixed-length time integration of :func:`march`, cycle by cycle.

    **Fields:**

    - `speed_rpm`, `omega_pinion` [rpm], [rad/s]; `mesh_period_s` ``T_m`` [s].
    - `s`: the uniform mesh-phase grid of one cycle, shape ``(n,)``.
    - `q`, `qd`: coordinates [m] and velocities [m/s] on that grid, shape ``(cycles, ndof, n)``;
      cycle ``c`` covers ``t = (first_cycle + c + s) T_m``.
    - `start_states`: ``(q, q')`` at mesh phase 0 of every cycle (Poincare samples), shape
      ``(cycles, 2 ndof)``; `final_state`, `final_reaction_N`: what the next cycle starts from
      (pass them back as `initial_state`, `reaction_N` to continue the run exactly).
    - `dte_mean_um`, `dte_rms_um`, `dte_p2p_um`: per-cycle DTE read-outs, shape ``(cycles,)``
      (mean and RMS by the quadrature rule of :func:`simulate`, peak-to-peak over its nodes
      and the grid).
    - `reaction_force_N`: output force used in every cycle (``"reaction"``; zeros otherwise).
    - `last_summary`: :func:`~hbgear.gear.readouts.periodic_summary` over the last cycle (means over
      that cycle; a power balance only once the run has settled).
    - `cycles`: cycles integrated (fewer than asked when `stopped_early`); `first_cycle`.
    - `u_static` [m]; `method`; `elapsed_s` [s]; `friction_law` used.
    """

    speed_rpm: float
    omega_pinion: float
    mesh_period_s: float
    s: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    start_states: np.ndarray
    final_state: np.ndarray
    final_reaction_N: float
    dte_mean_um: np.ndarray
    dte_rms_um: np.ndarray
    dte_p2p_um: np.ndarray
    reaction_force_N: np.ndarray
    last_summary: dict
    cycles: int
    first_cycle: int
    stopped_early: bool
    u_static: float
    method: str
    elapsed_s: float
    friction_law: Any


def _march_cycles(run, y, reaction, cycles, first_cycle, max_abs_dte_m):
    """Integrate `cycles` cycles from ``(y, reaction)``, or until ``|delta|`` exceeds
    `max_abs_dte_m`. **Returns:** ``(cycles done, their start states, (next state, next output
    force), stopped early)``."""
    kept, starts = [], []
    for k in range(cycles):
        starts.append(y)
        done = run.run_cycle(y, first_cycle + k, reaction)
        kept.append(done)
        y, reaction = run.next_start(done)
        if max_abs_dte_m is not None and max(np.max(np.abs(done.node_y[0])), np.max(np.abs(done.grid_y[0]))) > max_abs_dte_m:
            return kept, starts, (y, reaction), k + 1 < cycles
    return kept, starts, (y, reaction), False


def march(
    model,
    omega_pinion: float,
    cycles: int,
    *,
    initial_state=None,
    reaction_N: float | None = None,
    first_cycle: int = 0,
    rtol: float = 1e-9,
    atol: float | None = None,
    method: str = "LSODA",
    backend: str = "jax",
    samples_per_cycle: int | None = None,
    deflate_soft_mode: bool = False,
    max_abs_dte_m: float | None = None,
) -> MarchRecord:
    r"""Integrate exactly `cycles` mesh periods, with no steady-state test, keeping every cycle.

    The same piecewise integration as :func:`simulate` (one mechanism), for transients, growth
    in unstable zones and fixed-length runs. By default the soft output mode of ``"spring"`` is
    not deflated, so the response shows as it is; the ``"reaction"`` boundary always updates its
    output force between cycles (it defines that boundary in time integration).

    **Arguments:** as :func:`simulate`, and

    - `cycles`: mesh periods to integrate (>= 1).
    - `initial_state`: ``(q, q')`` at mesh phase 0, shape ``(2 ndof,)``; default quasi-static.
    - `reaction_N`: output force of the first cycle (``"reaction"``; default quasi-static).
    - `first_cycle`: index of the first cycle (time origin ``first_cycle T_m``), to continue a run.
    - `max_abs_dte_m`: stop after the first cycle in which ``|delta|`` exceeds this [m].

    **Returns:** a :class:`MarchRecord`.
    """
    start_time = time.perf_counter()
    if int(cycles) < 1:
        raise ValueError(f"cycles = {cycles!r}: an integer >= 1")
    run = _Integrator(model, omega_pinion, rtol=rtol, atol=atol, method=method, backend=backend,
                      samples_per_cycle=samples_per_cycle, deflate_soft_mode=deflate_soft_mode)
    model, ndof, omega = run.model, run.ndof, run.omega
    reaction = _initial_reaction(model, omega) if reaction_N is None else float(reaction_N)
    kept, starts, (final_state, final_reaction), stopped = _march_cycles(
        run, run.start_state(initial_state), reaction, int(cycles), first_cycle, max_abs_dte_m)
    delta_nodes = np.stack([c.node_y[0] for c in kept])
    mean = delta_nodes @ run.node_w
    rms = np.sqrt(((delta_nodes - mean[:, None]) ** 2) @ run.node_w)
    both = np.concatenate([delta_nodes, np.stack([c.grid_y[0] for c in kept])], axis=1)
    grid_y = np.stack([c.grid_y for c in kept])
    _, last_summary = _steady_summary(run, kept[-1:])  # means over the last cycle (LTI impulses as in simulate)
    return MarchRecord(
        speed_rpm=omega * 30.0 / math.pi,
        omega_pinion=omega,
        mesh_period_s=run.tm,
        s=run.grid_s,
        q=grid_y[:, :ndof],
        qd=grid_y[:, ndof:],
        start_states=np.stack(starts),
        final_state=final_state,
        final_reaction_N=float(final_reaction),
        dte_mean_um=1e6 * mean,
        dte_rms_um=1e6 * rms,
        dte_p2p_um=1e6 * np.ptp(both, axis=1),
        reaction_force_N=np.array([c.reaction for c in kept]),
        last_summary=last_summary,
        cycles=len(kept),
        first_cycle=int(first_cycle),
        stopped_early=stopped,
        u_static=run.u_static,
        method=method,
        elapsed_s=time.perf_counter() - start_time,
        friction_law=model.friction,
    )
