"""Linear gear models against closed forms: the static transmission error excitation (signs and
phases of eps and eps') and the proportional mesh damping c(t) = c k(t)/k_mean."""

from pathlib import Path

import numpy as np
import pytest
from scipy.linalg import expm

from hbgear.build import build_model
from hbgear.config import load_config
from hbgear.gear.simulate import simulate
from hbgear.gear.solve import rpm_to_rad_s, solve_periodic

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "paper_table1.toml"


def gear(*overrides):
    return build_model(load_config(EXAMPLE, list(overrides)))


def ti_coefficients(response, orders):
    """Complex Fourier coefficients ``<delta exp(-2 pi i n s)>`` of a steady mesh period of TI."""
    s, q, _, w = response.nodes
    return np.array([np.sum(w * q[0] * np.exp(-2j * np.pi * n * s)) for n in orders])


def hb_coefficients(solution, orders):
    """The same coefficients from the HB real basis ``a_n cos + b_n sin``: ``(a_n - i b_n)/2``."""
    c = solution.coefficients[0]
    return np.array([0.5 * (c[2 * n - 1] - 1j * c[2 * n]) for n in orders])


# ----------------------------------------------------------------------------- STE excitation

STE_UM, STE_DEG = (1.0, 0.4), (30.0, -50.0)
CONSTANT_K = ["mesh.k_max_MN_per_m=600.0", "mesh.k_mean_MN_per_m=600.0", "mesh.damping_ratio=0.05",
              "friction.law='none'", f"mesh.ste_amplitude_um={list(STE_UM)}", f"mesh.ste_phase_deg={list(STE_DEG)}"]


def ste_response_closed_form(model, omega):
    """Steady response to the STE alone, ``k`` constant: ``F_mesh = k (delta - eps) + c (delta' - eps')``,
    ``eps = sum_n A_n cos(n w_m t + phi_n)`` (t = 0 at a pair's entry). Harmonic ``n``,
    ``W = n w_m``: ``(K - W^2 M + i W C) Q_n = (k + i W c) A_n e^{i phi_n} e_1`` with, for the DTE
    alone, ``M = m_e``, ``K = k``, ``C = c``; for (delta, u) on the soft spring ``M = [[m_p, m_p],
    [m_p, m_p + m_g]]``, ``K = diag(k, k_u)``, ``C = diag(c, c_u)``. **Returns:** the complex
    coefficients ``<delta e^{-i n w_m t}> = Q_n[0] / 2``, n = 1, 2."""
    k, c, w_mesh = model.k_max_N_per_m, model.mesh_damping_Ns_per_m, model.teeth_pinion * omega
    if model.ndof == 1:
        mass, stiff, damp = np.array([[model.mass_equivalent_kg]]), np.array([[k]]), np.array([[c]])
    else:
        mp, mg = model.mass_pinion_kg, model.mass_gear_kg
        mass = np.array([[mp, mp], [mp, mp + mg]])
        stiff = np.diag([k, model.spring_stiffness_N_per_m])
        damp = np.diag([c, model.spring_damping_Ns_per_m])
    out = []
    for n, (amp, deg) in enumerate(zip(STE_UM, STE_DEG), start=1):
        big_w = n * w_mesh
        force = np.zeros(model.ndof, complex)
        force[0] = (k + 1j * big_w * c) * 1e-6 * amp * np.exp(1j * np.radians(deg))
        out.append(np.linalg.solve(stiff - big_w**2 * mass + 1j * big_w * damp, force)[0] / 2)
    return np.array(out)


@pytest.mark.parametrize("overrides", [
    ["friction.model='LTV'", "boundary.output='torques'"],
    ["friction.model='LTI'", "boundary.output='torques'"],
    ["friction.model='LTV'", "boundary.output='spring'", "boundary.damping_ratio=0.1"],
], ids=["LTV-torques", "LTI-torques", "LTV-spring"])
def test_ste_response_equals_the_closed_form(overrides):
    """Constant stiffness, no friction, two STE orders with phases: HB and time integration give
    the closed-form response at both orders (amplitude and phase), its mean N/k, and nothing at the
    other orders. A sign error in eps' or a phase convention cos(n w t - phi) fails here."""
    model = gear(*CONSTANT_K, *overrides)
    omega = rpm_to_rad_s(5000.0)
    expected = ste_response_closed_form(model, omega)
    assert np.all(np.abs(expected) > 1e-8)  # both orders respond (~0.5 um)
    solution = solve_periodic(model, omega, harmonics=8)
    np.testing.assert_allclose(hb_coefficients(solution, (1, 2)), expected, rtol=1e-10)  # measured 2e-12
    assert np.max(np.abs(hb_coefficients(solution, range(3, 9)))) < 1e-10 * np.max(np.abs(expected))
    assert solution.coefficients[0][0] == pytest.approx(model.normal_load_N / model.k_max_N_per_m, rel=1e-12)
    response = simulate(model, omega, period_cycles=(1,))
    np.testing.assert_allclose(ti_coefficients(response, (1, 2)), expected, rtol=1e-6)


# ----------------------------------------------------------------------------- proportional damping

PROPORTIONAL = ["friction.law='none'", "boundary.output='torques'", "mesh.damping_ratio=0.05"]


def exact_periodic_dte(model, omega):
    """Exact periodic DTE of ``m_e y'' + c_j y' + k_j y = N`` with ``k_j, c_j`` constant on the two
    pieces of the mesh period (double contact until ``Gamma - 1``, then single).

    On piece ``j`` (duration ``h_j``) ``x = (y, y')`` is ``x_j* + e^{A_j t} (x(t_j) - x_j*)``,
    ``x_j* = (N/k_j, 0)``; periodicity ``x(Tm) = x(0)`` is a 2x2 linear system. The Fourier
    coefficients follow exactly from ``int_0^h e^{A t} e^{-i W t} dt = (A - i W)^-1 (e^{(A - i W) h} - I)``.
    **Returns:** ``(coefficient(n) -> <y e^{-i n w_m t}>, y(s) on a grid)``.
    """
    me, load = model.mass_equivalent_kg, model.normal_load_N
    tm = 2 * np.pi / (model.teeth_pinion * omega)
    g1 = model.contact_ratio - 1.0
    pieces = []
    for k, lo, hi in ((model.k_max_N_per_m, 0.0, g1), (model.k_min_N_per_m, g1, 1.0)):
        c = float(model.mesh_damping(np.array([0.5 * (lo + hi)]))[0])
        a = np.array([[0.0, 1.0], [-k / me, -c / me]])
        pieces.append((a, np.array([load / k, 0.0]), lo * tm, (hi - lo) * tm))
    (a1, p1, _, h1), (a2, p2, _, h2) = pieces
    e1, e2 = expm(a1 * h1), expm(a2 * h2)
    # x0 = p2 + e2 (p1 + e1 (x0 - p1) - p2)
    x0 = np.linalg.solve(np.eye(2) - e2 @ e1, p2 + e2 @ (p1 - e1 @ p1 - p2))
    starts = [x0, p1 + e1 @ (x0 - p1)]

    def coefficient(n):
        big_w = n * 2 * np.pi / tm
        total = 0.0
        for (a, p, t0, h), x in zip(pieces, starts):
            shifted = a - 1j * big_w * np.eye(2)
            integral = np.linalg.solve(shifted, expm(shifted * h) - np.eye(2)) @ (x - p)
            constant = p[0] * ((np.exp(-1j * big_w * h) - 1) / (-1j * big_w) if n else h)
            total += np.exp(-1j * big_w * t0) * (integral[0] + constant)
        return total / tm

    def dte(s):
        s = np.asarray(s)
        out = np.empty(s.shape)
        for (a, p, t0, h), x in zip(pieces, starts):
            inside = (s * tm >= t0) & (s * tm < t0 + h)
            lam, vec = np.linalg.eig(a)  # e^{A t} = V e^{lam t} V^-1 (two distinct eigenvalues)
            modes = np.linalg.solve(vec, x - p)
            out[inside] = p[0] + np.real(np.exp(np.outer(s[inside] * tm - t0, lam)) @ (vec[0] * modes))
        return out

    return coefficient, dte


@pytest.fixture(scope="module")
def proportional_case():
    model = gear(*PROPORTIONAL, "mesh.damping_model='proportional'")
    return model, rpm_to_rad_s(4000.0)


def test_proportional_damping_is_c_k_over_k_mean(proportional_case):
    model, _ = proportional_case
    s = np.array([0.1, 0.9])  # double, single contact
    c = model.mesh_damping_Ns_per_m
    np.testing.assert_allclose(model.mesh_damping(s), c * np.array([model.k_max_N_per_m, model.k_min_N_per_m])
                               / model.k_mean_N_per_m, rtol=1e-15)


def test_proportional_damping_response_equals_the_exact_piecewise_solution(proportional_case):
    """LTV, no friction, torques, 4000 rpm: time integration and harmonic balance (H = 64) against
    the exact piecewise-exponential periodic solution. Measured: mesh orders 1-6 within 1.0e-7
    (TI) and 3.8e-6 (HB, its truncation; 3.1e-5 at H = 32) of the first order's amplitude; DTE RMS
    within 5.5e-8 (TI) and 1.2e-7 (HB), HB mean 2.7e-7, HB p2p 2.8e-6. Constant damping instead
    changes the RMS by 6.3e-4 and the p2p by 5.9e-3, far outside these tolerances."""
    model, omega = proportional_case
    coefficient, dte = exact_periodic_dte(model, omega)
    orders = np.arange(1, 7)
    exact = np.array([coefficient(n) for n in orders])
    grid = (np.arange(20000) + 0.5) / 20000
    wave = dte(grid)
    rms, p2p = np.std(wave), np.ptp(wave)
    assert abs(coefficient(0) - np.mean(wave)) < 1e-9 * np.mean(wave)  # the two exact routes agree
    response = simulate(model, omega, period_cycles=(1,))
    np.testing.assert_allclose(ti_coefficients(response, orders), exact, rtol=0, atol=3e-7 * np.abs(exact[0]))
    assert response.summary["dte_rms_um"] == pytest.approx(1e6 * rms, rel=3e-7)
    solution = solve_periodic(model, omega, harmonics=64)
    np.testing.assert_allclose(hb_coefficients(solution, orders), exact, rtol=0, atol=1e-5 * np.abs(exact[0]))
    hb = solution.summary()
    assert hb["dte_mean_um"] == pytest.approx(1e6 * coefficient(0).real, rel=1e-6)
    assert hb["dte_rms_um"] == pytest.approx(1e6 * rms, rel=5e-7)
    assert hb["dte_p2p_um"] == pytest.approx(1e6 * p2p, rel=1e-5)
    constant = solve_periodic(gear(*PROPORTIONAL), omega, harmonics=64).summary()
    assert abs(constant["dte_rms_um"] / (1e6 * rms) - 1) > 3e-4
    assert abs(constant["dte_p2p_um"] / (1e6 * p2p) - 1) > 3e-3


def test_proportional_damping_multipliers(proportional_case):
    """Liouville: det(monodromy) = exp(-int c(t)/m_e dt) = exp(-c Tm/m_e) for both damping models
    (the mean of c k(t)/k_mean is c), to 1e-12; they differ from the constant-damping ones by
    2.6e-5, and Hill's method (H = 64) gives them to 1.2e-6."""
    from hbgear.engine.floquet import hill_multipliers
    from hbgear.engine.hb import HarmonicBalance
    from hbgear.gear.monodromy import multipliers_linear
    from hbgear.gear.system import GearSystem

    model, omega = proportional_case
    tm = 2 * np.pi / (model.teeth_pinion * omega)
    liouville = np.exp(-model.mesh_damping_Ns_per_m * tm / model.mass_equivalent_kg)
    exact = multipliers_linear(model, omega)
    constant = multipliers_linear(gear(*PROPORTIONAL), omega)
    assert np.prod(exact).real == pytest.approx(liouville, rel=1e-12)
    assert np.prod(constant).real == pytest.approx(liouville, rel=1e-12)
    apart = np.max(np.abs(np.sort_complex(exact) - np.sort_complex(constant)))
    hb = HarmonicBalance(1, 64, 1, 260)
    hill = hill_multipliers(hb, np.zeros(hb.size), omega, GearSystem(model))
    assert apart > 1e-5  # 2.6e-5: at zeta = 0.05 the damping's time variation moves them little
    assert np.max(np.abs(np.sort_complex(hill) - np.sort_complex(exact))) < 2.5e-6  # 1.2e-6 at H = 64
