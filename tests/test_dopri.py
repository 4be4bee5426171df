"""The compiled Dormand-Prince 5(4) integrator (hbgear.engine.dopri) against closed forms:
its tableau's order conditions, linear systems against the matrix exponential (with a jump of
the right-hand side at an interval edge), the error falling with the tolerance as a fifth-order
method's, and failures reported."""

from __future__ import annotations


import numpy as np
import pytest
from scipy.linalg import expm

from hbgear.engine import dopri


def test_the_tableau_has_the_orders_it_claims():
    a = [np.array(row) for row in dopri.DP54_A]
    c, b, e = np.array(dopri.DP54_C), np.array(dopri.DP54_B), np.array(dopri.DP54_E)
    for i in range(1, 7):
        assert a[i].sum() == pytest.approx(c[i], abs=1e-15)
    low = b - e  # the embedded fourth-order weights
    for k in range(5):
        assert b @ c**k == pytest.approx(1.0 / (k + 1), abs=1e-14)
    for k in range(4):
        assert low @ c**k == pytest.approx(1.0 / (k + 1), abs=1e-14)
    assert low @ c**4 != pytest.approx(0.2, abs=1e-6)  # only fourth order: the error estimate is not zero
    np.testing.assert_allclose(a[6], b[:6], atol=0)  # first same as last


def _run(f, y0, starts, ends, data, rtol, atol, max_steps=100_000):
    import jax
    import jax.numpy as jnp

    jax.config.update("jax_enable_x64", True)
    program = jax.jit(lambda y0, s, e, d, r, a: dopri.integrate_segments(f, y0, s, e, d, r, a, max_steps))
    y, steps, ok = program(jnp.asarray(y0), jnp.asarray(starts), jnp.asarray(ends), jnp.asarray(data), rtol, atol)
    return np.asarray(y), np.asarray(steps), bool(ok)


def _jax_linear(y, k):
    import jax.numpy as jnp

    return jnp.stack([y[1], -k * y[0] - 0.1 * y[1]])


def test_a_piecewise_linear_system_matches_the_product_of_matrix_exponentials():
    starts, ends, stiffness = np.array([0.0, 1.3, 2.0]), np.array([1.3, 2.0, 4.5]), np.array([4.0, 25.0, 9.0])
    exact = np.array([1.0, 0.0])
    for a, b, k in zip(starts, ends, stiffness):
        exact = expm((b - a) * np.array([[0.0, 1.0], [-k, -0.1]])) @ exact
    errors = []
    for rtol in (1e-5, 1e-7, 1e-9, 1e-11):
        y, steps, ok = _run(lambda t, y, k: _jax_linear(y, k), [1.0, 0.0], starts, ends, stiffness, rtol, rtol * 1e-2)
        assert ok and steps.shape == (3,) and np.all(steps > 0)
        errors.append(np.abs(y - exact).max())
        assert errors[-1] < 1e3 * rtol  # the global error follows the local tolerance
    # a fifth-order method's error scales with the tolerance (not with its 1/5 power, as steps do)
    slope = np.polyfit(np.log10([1e-5, 1e-7, 1e-9, 1e-11]), np.log10(errors), 1)[0]
    assert 0.7 < slope < 1.3, (errors, slope)


def test_steps_follow_the_fifth_order_rule():
    """Steps grow as tol^(-1/5): ten thousand times the tolerance, about 1/6.3 the steps."""
    counts = []
    for rtol in (1e-6, 1e-10):
        _, steps, ok = _run(lambda t, y, k: _jax_linear(y, k), [1.0, 0.0], [0.0], [20.0], [16.0], rtol, rtol * 1e-2)
        assert ok
        counts.append(int(steps.sum()))
    ratio = counts[1] / counts[0]
    assert 10 ** (4 / 5) / 1.6 < ratio < 10 ** (4 / 5) * 1.6, counts


def test_failures_are_reported_not_hidden():
    _, _, ok = _run(lambda t, y, k: _jax_linear(y, k), [1.0, 0.0], [0.0], [20.0], [16.0], 1e-10, 1e-12, max_steps=5)
    assert not ok  # too few steps allowed

    def blows_up(t, y, k):
        import jax.numpy as jnp

        return jnp.stack([y[0] ** 2, y[1]])  # y' = y^2 from 1: infinite at t = 1

    _, _, ok = _run(blows_up, [1.0, 0.0], [0.0], [2.0], [0.0], 1e-8, 1e-10)
    assert not ok


def test_the_vanderpol_oscillator_agrees_with_scipys_dop853():
    from scipy.integrate import solve_ivp

    def f(t, y, mu):
        import jax.numpy as jnp

        return jnp.stack([y[1], mu * (1 - y[0] ** 2) * y[1] - y[0]])

    starts, ends, mus = np.array([0.0, 3.0, 7.0]), np.array([3.0, 7.0, 10.0]), np.array([1.0, 2.0, 0.5])
    y, _, ok = _run(f, [2.0, 0.0], starts, ends, mus, 1e-11, 1e-13)
    reference = np.array([2.0, 0.0])
    for a, b, mu in zip(starts, ends, mus):
        sol = solve_ivp(lambda t, y: [y[1], mu * (1 - y[0] ** 2) * y[1] - y[0]], (a, b), reference, method="DOP853",
                        rtol=1e-13, atol=1e-14)
        reference = sol.y[:, -1]
    assert ok and np.abs(y - reference).max() < 1e-8
