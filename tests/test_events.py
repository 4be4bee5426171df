"""Jumps of the nonlinear force at state-dependent instants (hbgear.engine.events): a generic
oscillator with a gated force against time integration with located switchings, exactness in the
AFT samples, continuity through grazing; the gear pair's Jacobian with contact loss."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest
from jax.tree_util import register_dataclass
from scipy.integrate import solve_ivp

from hbgear.build import build_model
from hbgear.config import load_config
from hbgear.engine.hb import HarmonicBalance
from hbgear.engine.newton import newton
from hbgear.engine.system import PeriodicSystem, check_system
from hbgear.gear.solve import rpm_to_rad_s, solve_periodic
from hbgear.gear.system import GearSystem

BACKLASH = Path(__file__).resolve().parents[1] / "examples" / "backlash.toml"


class _Gate(PeriodicSystem):
    r"""``x'' + c x' + k x = f cos(w t) - a [x > d]``: a force that switches on while ``x`` exceeds
    ``d`` (as a friction load while teeth touch); the parameter is ``w``."""

    ndof = 1
    is_linear = False

    def mass_matrix(self, p, xp=np):
        return xp.ones((1, 1))

    def excitation_frequency(self, p):
        return p

    def force(self, s, q, qd, p, part, extra, xp=np):
        linear = self.forcing * xp.cos(2 * np.pi * s) - self.stiffness * q[0] - self.damping * qd[0]
        gated = -self.push * xp.where(q[0] > self.gap, 1.0, 0.0)
        return xp.stack([linear if part == "linear" else gated if part == "nonlinear" else linear + gated])


@register_dataclass
@dataclass(frozen=True)
class Gate(_Gate):
    damping: float = 0.2
    stiffness: float = 1.0
    forcing: float = 1.0
    push: float = 0.5
    gap: float = 0.6

    def event_functions(self, s, q, qd, p, xp=np):
        return xp.stack([q[0] - self.gap])


@register_dataclass
@dataclass(frozen=True)
class GateUndeclared(_Gate):
    """The same equations without the event declaration: the jumps alias at O(1/N)."""

    damping: float = 0.2
    stiffness: float = 1.0
    forcing: float = 1.0
    push: float = 0.5
    gap: float = 0.6


W = 0.9


def hb_solution(system, harmonics, samples):
    hb = HarmonicBalance(1, harmonics, 1, samples)
    result = newton(lambda z: hb.residual_and_jacobians(jnp.asarray(z), W, system)[:2],
                    lambda z: hb.residual(jnp.asarray(z), W, system), np.zeros(hb.size), tolerance=1e-13,
                    max_iterations=40)
    return result


def time_integration_coefficients(system, periods=60, samples=8192):
    """Mean, ``a_1``, ``b_1`` of the steady state by DOP853 with the switchings located as events."""
    period = 2 * math.pi / W

    def rhs(t, y, state):
        return [y[1], system.forcing * math.cos(W * t) - system.stiffness * y[0] - system.damping * y[1]
                - system.push * state]

    def event(t, y, state):
        return y[0] - system.gap

    event.terminal = True

    def run(y, t, t_end, dense):
        pieces, state = [], float(y[0] > system.gap)
        while t < t_end:
            sol = solve_ivp(rhs, (t, t_end), y, args=(state,), events=event, rtol=1e-12, atol=1e-14,
                            method="DOP853", dense_output=dense)
            pieces.append(sol)
            y, t = sol.y[:, -1].copy(), sol.t[-1]
            if sol.status == 1:  # switched: step off the surface along the new flow
                state = 1.0 - state
                dt = 1e-9 * period
                y, t = y + dt * np.asarray(rhs(t, y, state)), t + dt
        return y, t, pieces

    y, t, _ = run(np.zeros(2), 0.0, periods * period, False)
    _, _, pieces = run(y, t, t + period, True)
    times = t + np.arange(samples) * period / samples
    x = np.empty(samples)
    for sol in pieces:
        inside = (times >= sol.t[0]) & (times <= sol.t[-1])
        x[inside] = sol.sol(times[inside])[0]
    c = np.fft.rfft(x) / samples
    return np.array([c[0].real, 2 * c[1].real, -2 * c[1].imag])


def test_gated_force_matches_time_integration_with_located_switchings():
    """HB with the event declared (H = 80) equals time integration with located switchings in the
    mean and first harmonic to 1e-7 (the H-truncation; 6e-11 .. 1.5e-9 at H = 160)."""
    system = Gate()
    check_system(system, W)
    result = hb_solution(system, 80, 324)
    assert result.converged
    reference = time_integration_coefficients(system)
    np.testing.assert_allclose(np.asarray(result.z)[:3], reference, rtol=0, atol=1e-7 * np.abs(reference).max())


def test_gated_force_is_exact_in_the_samples_and_undeclared_jumps_alias():
    """Q_nl is piecewise constant: with its jumps corrected the projection is exact, so N = 4H+4
    and 16 times more samples agree to rounding; undeclared, the sampled jumps alias and the
    answer moves by ~1e-2 at N = 4H+4."""
    few, many = hb_solution(Gate(), 20, 84), hb_solution(Gate(), 20, 1344)
    assert few.converged and many.converged
    np.testing.assert_allclose(np.asarray(few.z), np.asarray(many.z), rtol=0, atol=1e-13)
    blind = hb_solution(GateUndeclared(), 20, 84)
    assert np.max(np.abs(np.asarray(blind.z) - np.asarray(many.z))) > 1e-3


def test_residual_is_continuous_when_a_pulse_first_covers_a_sample():
    """``x = m + A cos(2 pi (t - t_0))`` with its peak between two samples: as ``m`` lifts the peak
    through the gap, the pulse ``x > d`` is located before it covers a sample (an excursion), so the
    corrected residual does not move when the first sample enters it; undeclared, it jumps by
    about ``a/N`` there."""
    harmonics, samples = 8, 64
    hb = HarmonicBalance(1, harmonics, 1, samples)
    t0, amplitude = 0.3 / samples, 0.3
    enter = amplitude * (1 - math.cos(2 * math.pi * t0))  # depth at which the sample at t = 0 enters

    def residual(system, depth):
        z = np.zeros(hb.size)
        z[0] = Gate.gap - amplitude + depth
        z[1], z[2] = amplitude * math.cos(2 * math.pi * t0), amplitude * math.sin(2 * math.pi * t0)
        return np.asarray(hb.residual(jnp.asarray(z), W, system))

    def step(system):
        return np.max(np.abs(residual(system, enter * (1 + 1e-7)) - residual(system, enter * (1 - 1e-7))))

    assert step(GateUndeclared()) > 0.5 * Gate.push / samples
    assert step(Gate()) < 1e-6 * Gate.push / samples
    # and the pulse is born continuously
    assert np.max(np.abs(residual(Gate(), 1e-13) - residual(Gate(), -1e-13))) < 1e-8


@pytest.mark.parametrize("formulation, law", [("A", "coulomb"), ("B", "arctan")])
def test_gear_jacobian_with_contact_loss_equals_finite_differences(formulation, law):
    """Backlash with friction at 13400 rpm (the teeth separate twice a mesh period): dR/dz with the
    event jumps equals central differences."""
    model = build_model(load_config(BACKLASH, [f"friction.law={law}", "friction.mu0=0.1",
                                               f"friction.formulation={formulation}"]))
    omega = rpm_to_rad_s(13400.0)
    sol = solve_periodic(model, omega, harmonics=12, samples=256)
    hb, system = HarmonicBalance(2, 12, 1, 256), GearSystem(model)
    z = np.asarray(sol.z)
    _, jz, _ = hb.residual_and_jacobians(jnp.asarray(z), omega, system)
    h = 1e-7
    fd = np.empty((hb.size, hb.size))
    for j in range(hb.size):
        e = np.zeros(hb.size)
        e[j] = h
        fd[:, j] = (np.asarray(hb.residual(z + e, omega, system)) - np.asarray(hb.residual(z - e, omega, system))) / (2 * h)
    np.testing.assert_allclose(np.asarray(jz), fd, atol=1e-8 * np.abs(fd).max())


@register_dataclass
@dataclass(frozen=True)
class LeavingSpring(_Gate):
    r"""``x'' + c x' + k x = f cos(w t) - k_c max(x - d, 0) [s < s_b]``: a contact spring that
    carries load while ``x > d`` and only before the phase ``s_b`` (a tooth pair that leaves the path
    of contact there): a kink where ``x`` crosses ``d`` (an event), a jump at ``s_b`` (a breakpoint)."""

    damping: float = 0.2
    stiffness: float = 1.0
    forcing: float = 1.0
    push: float = 0.0
    gap: float = 0.6
    contact: float = 3.0
    leaves: float = 0.43

    def breakpoints(self, p, xp=np):
        return xp.asarray([self.leaves])

    def force(self, s, q, qd, p, part, extra, xp=np):
        linear = self.forcing * xp.cos(2 * np.pi * s) - self.stiffness * q[0] - self.damping * qd[0]
        spring = -self.contact * xp.maximum(q[0] - self.gap, 0.0) * xp.where(s < self.leaves, 1.0, 0.0)
        return xp.stack([linear if part == "linear" else spring if part == "nonlinear" else linear + spring])

    def event_functions(self, s, q, qd, p, xp=np):
        return xp.stack([q[0] - self.gap])


def test_residual_is_continuous_where_a_kink_moves_onto_a_breakpoint():
    """``x = m + A cos(2 pi (t - t_0))`` falls through ``d`` near ``s_b``: as ``m`` moves that zero
    across the breakpoint, the kink ``k_c x'`` of the force leaves the located zeros and sits at the
    breakpoint, where the force also jumps. Its correction must follow it there: the residual is
    continuous across the crossing (it stepped by the kink's ``O(1/N^2)`` correction, ~1e-4 here,
    when only the kinks at the zeros were corrected)."""
    harmonics, samples = 8, 64
    hb = HarmonicBalance(1, harmonics, 1, samples)
    system = LeavingSpring()
    amplitude, t0 = 0.3, 0.2
    # the falling zero of x - d at t_b = s_b when m = d - A cos(2 pi (s_b - t0))
    m_b = system.gap - amplitude * math.cos(2 * math.pi * (system.leaves - t0))

    def residual(m):
        z = np.zeros(hb.size)
        z[0] = m
        z[1], z[2] = amplitude * math.cos(2 * math.pi * t0), amplitude * math.sin(2 * math.pi * t0)
        return np.asarray(hb.residual(jnp.asarray(z), W, system))

    # dt_c/dm = 1/|x'(t_b)| ~ 0.6: dm = 1e-7 moves the zero 6e-8 (far outside the 1e-10 the jumps are
    # measured across) to either side of the breakpoint
    steps = [np.max(np.abs(residual(m_b + dm) - residual(m_b - dm))) for dm in (1e-5, 1e-6, 1e-7)]
    assert steps[2] < 1e-6, steps  # continuous: the step is the slope times 2 dm
    assert steps[0] / steps[1] > 5 and steps[1] / steps[2] > 5, steps  # and shrinks with dm


def test_declared_probes_by_tracing_and_falls_back_for_value_reading_systems():
    """events.declared answers without running the system (its arguments are tracers: nothing is
    compiled) and still answers for a system whose event functions read their arguments' values."""
    import jax

    from hbgear.engine.events import declared

    seen = []

    @register_dataclass
    @dataclass(frozen=True)
    class Watching(Gate):
        def event_functions(self, s, q, qd, p, xp=np):
            seen.append(isinstance(q, jax.core.Tracer))
            return super().event_functions(s, q, qd, p, xp)

    @register_dataclass
    @dataclass(frozen=True)
    class Reading(Gate):
        def event_functions(self, s, q, qd, p, xp=np):
            return xp.asarray(np.asarray(q)[0] - self.gap)[None]  # needs values: fails in a trace

    assert declared(Watching(), W) and seen == [True]
    assert declared(Reading(), W)
    assert not declared(GateUndeclared(), W)
    assert declared(Gate(), jnp.float64(W))
