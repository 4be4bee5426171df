"""hbgear.engine.newton: the one damped Newton, its statuses and its bordered form.

Known answers: ``z^2 = 2`` (``sqrt 2``), ``atan(5 z) = 0.3`` (``tan(0.3) / 5``, where the full
step overshoots from ``|5 z| > 1.4`` and the line search must act), the unit circle cut by the
line ``z + p = 1.2`` (closed form); failures built to happen: no real root, a zero Jacobian, a
residual outside its domain.
"""

import math
import warnings

import numpy as np
import pytest
import scipy.linalg

from hbgear.engine.newton import NewtonStatus, newton


class Counted:
    def __init__(self, f):
        self.f, self.calls = f, 0

    def __call__(self, z):
        self.calls += 1
        return self.f(z)


def scalar(f, df):
    return (lambda z: (np.array([f(z[0])]), np.array([[df(z[0])]]))), (lambda z: np.array([f(z[0])]))


def test_converges_to_the_root_with_a_message():
    rj, r = scalar(lambda z: z * z - 2, lambda z: 2 * z)
    result = newton(rj, r, [1.0], tolerance=1e-14)
    assert result.status == NewtonStatus.CONVERGED and result.converged
    assert result.z[0] == pytest.approx(math.sqrt(2), rel=1e-15)
    assert result.residual_norm <= 1e-14 and 3 <= result.iterations <= 6
    assert result.jacobian[0, 0] == pytest.approx(2 * math.sqrt(2), rel=1e-14)  # dR/dz at the root
    assert "converged" in result.message


def test_line_search_lands_where_the_full_step_overshoots():
    f, df = (lambda z: math.atan(5 * z) - 0.3), (lambda z: 5 / (1 + 25 * z * z))
    rj, r = scalar(f, df)
    z0 = 0.6  # the full Newton step from here lands at |5 z| > 3: max|R| grows
    assert abs(f(z0 - f(z0) / df(z0))) > abs(f(z0))
    result = newton(rj, r, [z0], tolerance=1e-13)
    assert result.converged and result.z[0] == pytest.approx(math.tan(0.3) / 5, abs=1e-13)


def test_full_step_jacobian_is_the_same_iteration_with_fewer_calls():
    """Evaluating the full step with its Jacobian changes the calls, not the iterates."""
    f, df = (lambda z: math.atan(5 * z) - 0.3), (lambda z: 5 / (1 + 25 * z * z))
    runs = {}
    for at_full_step in (False, True):
        rj, r = (Counted(g) for g in scalar(f, df))
        result = newton(rj, r, [0.6], tolerance=1e-13, jacobian_at_full_step=at_full_step)
        runs[at_full_step] = result, rj.calls, r.calls
    (plain, rj0, r0), (full, rj1, r1) = runs[False], runs[True]
    assert plain.converged and plain.iterations == full.iterations and np.array_equal(plain.z, full.z)
    assert rj0 == plain.iterations + 1  # once at z0, once per iteration
    assert r0 - r1 == plain.iterations  # each full step: (R, J) at once instead of R first
    assert rj1 > rj0  # ... wasted where the line search had to act (from 0.6 it does)


def test_no_real_root_is_max_iterations():
    rj, r = scalar(lambda z: z * z + 1, lambda z: 2 * z)
    result = newton(rj, r, [0.5], max_iterations=7)
    assert result.status == NewtonStatus.MAX_ITERATIONS and not result.converged
    assert result.iterations == 7 and result.residual_norm >= 1.0
    assert "max iterations" in result.message and "try" in result.message


def test_zero_jacobian_is_singular():
    rj, r = scalar(lambda z: z * z + 1, lambda z: 2 * z)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", scipy.linalg.LinAlgWarning)
        result = newton(rj, r, [0.0])
    assert result.status == NewtonStatus.SINGULAR_JACOBIAN and result.iterations == 0
    assert result.z[0] == 0.0 and result.residual_norm == 1.0  # where it stopped, not a NaN iterate
    assert "singular" in result.message


def test_residual_outside_its_domain_is_nonfinite():
    with np.errstate(invalid="ignore"):
        rj, r = scalar(lambda z: np.log(z), lambda z: 1 / z)
        result = newton(rj, r, [-1.0])
    assert result.status == NewtonStatus.NONFINITE and result.iterations == 0
    assert "not finite" in result.message


def test_bordered_system_leaves_the_constraint_out_of_the_norm():
    """``z^2 + p^2 = 1`` bordered by the constraint ``c = 1e6 (z + p - 1.2)``: max|R| is the
    circle equation's alone, ``c`` is held to its own tolerance, and Newton from a point on the
    line lands on the closed-form intersection."""
    scale = 1e6

    def rj(y):
        z, p = y
        return np.array([z * z + p * p - 1, scale * (z + p - 1.2)]), np.array([[2 * z, 2 * p], [scale, scale]])

    def r(y):
        return rj(y)[0]

    options = dict(tolerance=1e-15, constraints=1, constraint_tolerance=1e-8)
    off_line = newton(rj, r, [0.9, 0.301], max_iterations=0, **options)  # c = 1000 there
    assert off_line.residual_norm == pytest.approx(abs(0.81 + 0.301**2 - 1), rel=1e-12)
    on_circle = newton(rj, r, [1.0, 0.0], max_iterations=0, **options)  # R = 0, c = -2e5
    assert on_circle.residual_norm == 0.0 and on_circle.status == NewtonStatus.MAX_ITERATIONS
    result = newton(rj, r, [0.9, 0.3], **options)
    assert result.converged, result.message
    z, p = result.z
    assert z == pytest.approx(0.6 + math.sqrt(0.14), rel=1e-14)  # z^2 - 1.2 z + 0.22 = 0, the root near the start
    assert result.residual_norm == abs(z * z + p * p - 1) <= 1e-15
    assert abs(scale * (z + p - 1.2)) <= 1e-8
