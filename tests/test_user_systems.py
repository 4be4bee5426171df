"""User-defined periodic systems through the public API, each against a route that shares no code
with the engine: the damped Mathieu oscillator (exact Mathieu characteristic values from SciPy,
an independent monodromy by SciPy integration) and a two-mass oscillator with dry friction (SciPy
time integration). Also the contract checks and the API's misuse errors."""

from __future__ import annotations

from dataclasses import dataclass

import jax
import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq
from scipy.special import mathieu_a, mathieu_b

import hbgear
from hbgear.engine.monodromy import multipliers_linear


@jax.tree_util.register_dataclass
@dataclass(frozen=True)
class Mathieu(hbgear.PeriodicSystem):
    """``x'' + 2 zeta x' + (1 + eps cos(w t)) x = f cos(w t)``; parameter ``w``."""

    zeta: float = 0.0
    eps: float = 0.1
    forcing: float = 0.01

    ndof = 1
    is_linear = True
    coefficients_independent_of_parameter = True
    forcing_affine_in_frequency = True

    def mass_matrix(self, p, xp=np):
        return xp.ones((1, 1))

    def excitation_frequency(self, p):
        return p

    def force(self, s, q, qd, p, part, extra, xp=np):
        c = xp.cos(2 * np.pi * s)
        linear = self.forcing * c - (1.0 + self.eps * c) * q[0] - 2 * self.zeta * qd[0]
        return xp.stack([linear if part != "nonlinear" else 0.0 * linear])


@jax.tree_util.register_dataclass
@dataclass(frozen=True)
class Rubbing(hbgear.PeriodicSystem):
    """Two unit masses, springs k - k - k, dampers c; mass 2 rubs with ``mu N tanh(x2' / v)``."""

    damping: float = 0.05
    forcing: float = 0.2
    friction: float = 0.05
    v_eps: float = 0.05

    ndof = 2
    is_linear = False
    coefficients_independent_of_parameter = True
    forcing_affine_in_frequency = True
    nonlinear_force_uses_displacement = False

    def mass_matrix(self, p, xp=np):
        return xp.eye(2)

    def excitation_frequency(self, p):
        return p

    def force(self, s, q, qd, p, part, extra, xp=np):
        c = self.damping
        linear = xp.stack([self.forcing * xp.cos(2 * np.pi * s) - 2 * q[0] + q[1] - c * qd[0], -2 * q[1] + q[0] - c * qd[1]])
        rub = xp.stack([0.0 * qd[0], -self.friction * xp.tanh(qd[1] / self.v_eps)])
        return {"linear": linear, "nonlinear": rub, "all": linear + rub}[part]


def _tongue_edges(eps: float) -> tuple[float, float]:
    """Edges of the principal tongue of the undamped ``x'' + (1 + eps cos w t) x = 0``: with
    ``tau = w t / 2`` it is Mathieu's ``x'' + (a - 2 q cos 2 tau) x = 0`` (sign of q immaterial) with
    ``a = 4 / w^2``, ``q = 2 eps / w^2``; the edges are ``a = b_1(q)`` and ``a = a_1(q)``."""
    def edge(char):
        return brentq(lambda w: 4 / w**2 - char(1, 2 * eps / w**2), 1.5, 2.5, xtol=1e-14)

    low, high = sorted((edge(mathieu_b), edge(mathieu_a)))
    return low, high


def _monodromy_by_scipy(system: Mathieu, w: float) -> np.ndarray:
    """Monodromy over one period 2 pi / w by integrating the homogeneous equation (SciPy only)."""
    def rhs(t, y):
        x, v = y[:2], y[2:]
        return np.concatenate([v, -(1 + system.eps * np.cos(w * t)) * x - 2 * system.zeta * v])

    y0 = np.array([1.0, 0.0, 0.0, 1.0])  # columns (x, v) of the identity, stacked as (x1, x2, v1, v2)
    sol = solve_ivp(rhs, (0, 2 * np.pi / w), y0, method="DOP853", rtol=1e-12, atol=1e-14)
    y = sol.y[:, -1]
    return np.array([[y[0], y[1]], [y[2], y[3]]])


def test_mathieu_tongue_edges_are_the_exact_characteristic_values():
    """Exact monodromy of the engine: unstable just inside both exact edges, stable just outside."""
    eps = 0.2
    low, high = _tongue_edges(eps)
    assert 1.85 < low < 1.95 and 2.05 < high < 2.15
    system = Mathieu(eps=eps)
    d = 1e-4
    mod = np.abs(multipliers_linear(system, np.array([low - d, low + d, high - d, high + d]))).max(axis=1)
    assert mod[0] <= 1 + 1e-9 and mod[1] > 1 + 1e-6 and mod[2] > 1 + 1e-6 and mod[3] <= 1 + 1e-9


@pytest.mark.parametrize("w", [1.7, 1.95, 2.05, 2.3])
def test_mathieu_multipliers_hill_and_exact_equal_an_independent_integration(w):
    system = Mathieu(zeta=0.01, eps=0.2)
    want = np.sort_complex(np.linalg.eigvals(_monodromy_by_scipy(system, w)))
    exact = np.sort_complex(multipliers_linear(system, w))
    np.testing.assert_allclose(exact, want, rtol=0, atol=1e-9)
    hill = hbgear.solve(system, parameter=w, harmonics=16).multipliers  # through the API: exact for a linear system
    np.testing.assert_allclose(np.sort_complex(hill), want, rtol=0, atol=1e-9)
    from hbgear.engine.floquet import hill_multipliers
    from hbgear.engine.hb import HarmonicBalance

    hb = HarmonicBalance(1, 16, 1, 64)
    by_hill = hill_multipliers(hb, np.zeros(hb.size), w, system)
    assert np.max(np.abs(np.sort(np.abs(by_hill)) - np.sort(np.abs(want)))) < 1e-8


def test_mathieu_curve_is_unstable_exactly_inside_the_tongue():
    system = Mathieu(zeta=0.0, eps=0.2)
    curve = hbgear.frequency_response(system, parameter=(1.6, 2.4), harmonics=12, progress=False)
    assert curve.success, curve.message
    low, high = _tongue_edges(0.2)
    inside = (curve.parameter > low + 1e-3) & (curve.parameter < high - 1e-3)
    outside = (curve.parameter < low - 1e-3) | (curve.parameter > high + 1e-3)
    assert np.all(curve.stable[inside] == 0) and np.all(curve.stable[outside] == 1)
    zones = curve.unstable_zones
    assert len(zones) == 1
    assert zones[0]["parameter_from"] == pytest.approx(low, abs=2 * zones[0]["resolution"])
    assert zones[0]["parameter_to"] == pytest.approx(high, abs=2 * zones[0]["resolution"])


def _rubbing_by_scipy(system: Rubbing, w: float, periods: int = 150) -> float:
    """max |x1| over the last period of a DOP853 run from rest (SciPy only)."""
    c = system.damping

    def rhs(t, y):
        x1, x2, v1, v2 = y
        return [v1, v2, system.forcing * np.cos(w * t) - 2 * x1 + x2 - c * v1,
                -2 * x2 + x1 - c * v2 - system.friction * np.tanh(v2 / system.v_eps)]

    T = 2 * np.pi / w
    sol = solve_ivp(rhs, (0, periods * T), [0, 0, 0, 0], method="DOP853", rtol=1e-11, atol=1e-13,
                    t_eval=np.linspace((periods - 1) * T, periods * T, 4001))
    return float(np.max(np.abs(sol.y[0])))


def test_dry_friction_oscillator_equals_time_integration():
    system = Rubbing()
    curve = hbgear.frequency_response(system, parameter=(0.6, 2.0), harmonics=15, samples=256, progress=False)
    assert curve.success, curve.message
    i = int(np.argmin(np.abs(curve.parameter - 1.2)))
    w = float(curve.parameter[i])
    z = np.pad(curve.z[i].reshape(2, -1), ((0, 0), (0, 40))).ravel()  # the same waveform at H = 35
    sol = hbgear.solve(system, parameter=w, harmonics=35, samples=512, z0=z)
    ti = _rubbing_by_scipy(system, w)
    assert sol.max_abs(0) == pytest.approx(ti, rel=2e-5)
    assert sol.multipliers is not None and np.all(np.abs(sol.multipliers) < 1)  # damped: stable
    assert np.all(curve.stable == 1)


def test_contract_violations_are_named():
    @jax.tree_util.register_dataclass
    @dataclass(frozen=True)
    class WrongShape(Mathieu):
        def force(self, s, q, qd, p, part, extra, xp=np):
            return xp.stack([q[0], q[0]])  # two rows for one coordinate

    with pytest.raises(ValueError, match=r"WrongShape.force.*\(1, 2\)"):
        hbgear.solve(WrongShape(), parameter=2.0, harmonics=4)

    @jax.tree_util.register_dataclass
    @dataclass(frozen=True)
    class NotLinear(Mathieu):
        def force(self, s, q, qd, p, part, extra, xp=np):
            return xp.stack([q[0] ** 3 + 0.0 * s])

    with pytest.raises(ValueError, match="is_linear is True"):
        hbgear.solve(NotLinear(), parameter=2.0, harmonics=4)

    with pytest.raises(TypeError, match="not a hbgear.PeriodicSystem"):
        hbgear.check_system(object(), 1.0)


def test_api_misuse_is_a_type_error():
    with pytest.raises(TypeError, match="parameter="):
        hbgear.solve(Mathieu(), speed_rpm=1000.0)
    with pytest.raises(TypeError, match="GearPairModel"):
        hbgear.frequency_response("not a model", parameter=(1.0, 2.0))
