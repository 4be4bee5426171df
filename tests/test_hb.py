"""Harmonic balance, checked by independent routes: time integration, finite differences,
direct linear solves, energy balance, convergence in H and in the friction regularisation."""

from __future__ import annotations

from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest

from hbgear.engine import fourier
from hbgear.build import build_model
from hbgear.config import load_config
from hbgear.engine.hb import HarmonicBalance
from hbgear.gear.simulate import simulate
from hbgear.gear.solve import auto_harmonics, rpm_to_rad_s, solve_periodic
from hbgear.gear.system import GearSystem

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "paper_table1.toml"


def model_with(*overrides):
    return build_model(load_config(EXAMPLE, list(overrides)))


# -- the Fourier machinery -----------------------------------------------------------------------


def test_convolution_matrix_is_the_product_in_time():
    """T(p) x equals the projection of p(t) x(t) sampled finely (p with harmonics up to 2H)."""
    rng = np.random.default_rng(1)
    harmonics, samples = 6, 64
    x = rng.normal(size=2 * harmonics + 1)
    p = rng.normal(size=2 * harmonics + 1) + 1j * rng.normal(size=2 * harmonics + 1)
    p[0] = p[0].real
    tau = 2 * np.pi * np.arange(samples) / samples
    p_t = p[0].real + 2 * np.real(sum(p[m] * np.exp(1j * m * tau) for m in range(1, 2 * harmonics + 1)))
    product = fourier.project(p_t * fourier.synthesize(x, harmonics, samples), harmonics)
    np.testing.assert_allclose(fourier.convolution_matrix(p, harmonics) @ x, product, atol=1e-12)


def test_derivative_matrix_differentiates():
    harmonics, samples, omega = 5, 64, 3.0
    x = np.random.default_rng(2).normal(size=2 * harmonics + 1)
    tau = 2 * np.pi * np.arange(samples) / samples
    k = np.arange(1, harmonics + 1)
    expected = omega * (np.cos(np.outer(tau, k)) @ (k * x[2::2]) - np.sin(np.outer(tau, k)) @ (k * x[1::2]))
    np.testing.assert_allclose(
        fourier.synthesize(fourier.derivative_matrix(harmonics, omega) @ x, harmonics, samples), expected, atol=1e-12
    )


# -- linear algebra of the LTV problem (Eq. 23) ---------------------------------------------------


def test_ltv_newton_equals_direct_kh_solve():
    """Newton from a random start lands on the direct solve of K_h(w) X = F(w)."""
    model = model_with("boundary.output=torques")
    hb, system, omega = HarmonicBalance(1, 16, 1, 64), GearSystem(model), rpm_to_rad_s(5000)
    k_h, forcing, _ = hb.linear_operator(system, omega)
    direct = np.linalg.solve(np.asarray(k_h), np.asarray(forcing))
    start = np.random.default_rng(3).normal(size=hb.size)
    solution = solve_periodic(model, omega, harmonics=16, samples=64, z0=start)
    np.testing.assert_allclose(solution.coefficients.ravel(), direct, rtol=1e-10, atol=1e-18)


@pytest.mark.parametrize("overrides, uses_q", [
    (("friction.model=NLTV", "friction.formulation=B"), True),
    (("friction.model=NLTV", "friction.formulation=A"), False),  # the Jacobian skips the q-blocks
    (("friction.model=NLTV", "friction.formulation=A", "mesh.backlash_um=20"), True),
    (("friction.model=LTV", "friction.formulation=B", "mesh.backlash_um=20"), True),
], ids=["NLTV-B", "NLTV-A", "NLTV-A-backlash", "LTV-B-backlash"])
def test_jax_jacobian_equals_finite_differences(overrides, uses_q):
    """Nonlinear models (arctan, spring): dR/dz and dR/dp against central differences, whatever
    the system declares about ``Q_nl``'s dependence on ``q`` (a wrong False fails here)."""
    model = model_with("friction.law=arctan", "mesh.damping_ratio=0.05", *overrides)
    hb, system, omega = HarmonicBalance(2, 6, 1, 64), GearSystem(model), rpm_to_rad_s(3000)
    assert system.nonlinear_force_uses_displacement is uses_q
    z = np.random.default_rng(4).normal(size=hb.size) * 0.3
    z[0] = 1.0
    _, jz, jp = hb.residual_and_jacobians(jnp.asarray(z), omega, system)
    h = 1e-6
    fd = np.empty((hb.size, hb.size))
    for j in range(hb.size):
        e = np.zeros(hb.size)
        e[j] = h
        fd[:, j] = (np.asarray(hb.residual(z + e, omega, system)) - np.asarray(hb.residual(z - e, omega, system))) / (2 * h)
    np.testing.assert_allclose(np.asarray(jz), fd, atol=1e-6 * np.abs(fd).max())
    hp = 1e-3 * omega
    fd_p = (np.asarray(hb.residual(z, omega + hp, system)) - np.asarray(hb.residual(z, omega - hp, system))) / (2 * hp)
    np.testing.assert_allclose(np.asarray(jp), fd_p, atol=1e-6 * np.abs(fd_p).max())


# -- against time integration ------------------------------------------------------------------


CASES = [
    pytest.param(("friction.formulation=A",), 2400.0, id="LTV-A-2400"),
    pytest.param(("friction.formulation=A",), 7000.0, id="LTV-A-7000"),
    pytest.param(("friction.formulation=B",), 2400.0, id="LTV-B-2400"),
    pytest.param(("friction.formulation=B",), 7000.0, id="LTV-B-7000"),
    pytest.param(
        ("friction.model=NLTV", "friction.law=arctan", "mesh.damping_ratio=0.05"), 3000.0, id="NLTV-arctan-3000"
    ),
]


@pytest.mark.parametrize("overrides, speed_rpm", CASES)
def test_hb_matches_time_integration(overrides, speed_rpm):
    """RMS within 0.5 % and peak-to-peak within 1 % of time integration (spring boundary, H=32)."""
    model = model_with("boundary.damping_ratio=0.1", *overrides)
    omega = rpm_to_rad_s(speed_rpm)
    hb = solve_periodic(model, omega, harmonics=32, samples=256).summary()
    ti = simulate(model, omega).summary
    assert hb["dte_rms_um"] == pytest.approx(ti["dte_rms_um"], rel=5e-3)
    assert hb["dte_p2p_um"] == pytest.approx(ti["dte_p2p_um"], rel=1e-2)
    assert hb["dynamic_factor"] == pytest.approx(ti["dynamic_factor"], rel=1e-2)


# -- energy balance, convergence ---------------------------------------------------------------


@pytest.mark.parametrize(
    "overrides",
    [("friction.formulation=A",), ("friction.formulation=B",), ("friction.model=NLTV", "friction.law=arctan")],
    ids=["LTV-A", "LTV-B", "NLTV"],
)
def test_energy_balance_from_hb(overrides):
    """Net input power = friction loss + <F_mesh delta'> within 0.5 % (spring boundary)."""
    model = model_with("mesh.damping_ratio=0.05", *overrides)
    s = solve_periodic(model, rpm_to_rad_s(4000), harmonics=24, samples=256).summary()
    assert s["mean_power_loss_W"] > 0.0
    assert s["mean_power_loss_W"] == pytest.approx(s["mean_friction_loss_W"] + s["mean_mesh_power_W"], rel=5e-3)


def test_error_falls_monotonically_with_harmonics():
    """LTV (torques): the DTE error against a H=96 reference falls as H grows."""
    model = model_with("boundary.output=torques")
    omega = rpm_to_rad_s(4000)
    reference = solve_periodic(model, omega, harmonics=96).state_at(np.linspace(0, 1, 400, endpoint=False))[0][0]
    errors = []
    for harmonics in (4, 8, 16, 32):
        dte = solve_periodic(model, omega, harmonics=harmonics).state_at(np.linspace(0, 1, 400, endpoint=False))[0][0]
        errors.append(np.sqrt(np.mean((dte - reference) ** 2)))
    assert all(b < a for a, b in zip(errors, errors[1:])), errors
    assert errors[-1] < 1e-2 * np.std(reference)


def test_coulomb_regularisation_converges():
    """NLTV Coulomb: the DTE RMS converges as the sgn regularisation velocity shrinks."""
    rms = []
    for v_reg in (0.02, 0.005, 0.00125):
        model = model_with("friction.model=NLTV", f"friction.regularization_m_per_s={v_reg}", "mesh.damping_ratio=0.05")
        rms.append(solve_periodic(model, rpm_to_rad_s(3000), harmonics=24, samples=256).summary()["dte_rms_um"])
    steps = np.abs(np.diff(rms))
    assert steps[1] < steps[0]
    assert steps[1] < 1e-3 * rms[-1]


def test_auto_harmonics_reports_h_and_meets_its_tail_criterion():
    model = model_with("boundary.output=torques")
    solution = auto_harmonics(model, rpm_to_rad_s(8000))
    _, amp, _ = fourier.harmonic_amplitudes(solution.coefficients[0], solution.harmonics)
    tail = np.sqrt(np.sum(amp[(3 * solution.harmonics) // 4 :] ** 2))
    assert tail <= 1e-3 * np.sqrt(np.sum(amp**2))
    assert solution.harmonics >= 16


# -- the speed-independent pieces of a sweep, against the full construction ---------------------


def test_frozen_operator_and_forcing_pieces_equal_the_full_construction():
    """L = A0 + w A1 + w^2 A2 and the forcing from its pieces equal the quadrature at every speed,
    with their speed derivatives (NLTV arctan, soft spring: the wind-up u_s(w) is in the mean)."""
    import jax

    model = model_with("friction.model=NLTV", "friction.law=arctan")
    hb, system = HarmonicBalance(model.ndof, 8, 1, 64), GearSystem(model)
    quad = hb.prepare(system)
    assert quad.frozen is not None and quad.frozen.forcing is not None
    full = quad._replace(frozen=None)
    for rpm in (2000.0, 9000.0, 13400.0, 21000.0):
        w = rpm_to_rad_s(rpm)
        fast, slow = jax.jvp(lambda p: hb.linear_operator(system, p, quad), (w,), (1.0,)), jax.jvp(
            lambda p: hb.linear_operator(system, p, full), (w,), (1.0,))
        for got, want, got_dp, want_dp in zip(fast[0], slow[0], fast[1], slow[1]):
            scale = float(jnp.max(jnp.abs(want)))  # derivatives on the scale of (value / w)
            assert scale > 0 and float(jnp.max(jnp.abs(got - want))) <= 1e-11 * scale
            assert float(jnp.max(jnp.abs(got_dp - want_dp))) <= 1e-11 * scale / w


def test_forcing_pieces_are_refused_when_the_declared_structure_does_not_hold():
    """A system that declares an affine forcing but is not: the check at a third speed refuses the
    pieces and the residual uses the quadrature (LTV arctan friction makes the forcing nonlinear in w)."""
    from dataclasses import dataclass

    from jax.tree_util import register_dataclass

    @register_dataclass
    @dataclass(frozen=True)
    class ClaimsAffine(GearSystem):
        @property
        def forcing_affine_in_frequency(self):
            return True

    model = model_with("friction.model=LTV", "friction.law=arctan", "friction.formulation='A'")
    honest, liar = GearSystem(model), ClaimsAffine(model)
    assert not honest.forcing_affine_in_frequency
    hb = HarmonicBalance(model.ndof, 8, 1, 64)
    quad = hb.prepare(liar)
    assert quad.frozen is not None and quad.frozen.forcing is None
    z, w = np.linspace(-1, 1, hb.size) * 1e-2, rpm_to_rad_s(13000.0)
    np.testing.assert_allclose(hb.residual(jnp.asarray(z), w, liar), hb.residual(jnp.asarray(z), w, honest),
                               rtol=0, atol=1e-13)


def test_frozen_pieces_first_asked_for_under_a_trace_are_concrete_and_equal():
    """The speed-independent pieces built inside an outer vmap (the cache is empty) are concrete
    arrays, equal to those built outside a trace."""
    import jax

    from hbgear.engine import hb as hb_module

    model = model_with("friction.model=NLTV", "friction.law=arctan")
    hb, system = HarmonicBalance(model.ndof, 6, 1, 64), GearSystem(model)
    hb_module._FROZEN.clear()
    seen = []

    def inside(x):
        seen.append(hb.prepare(system).frozen)
        return x

    jax.vmap(inside)(jnp.ones(2))
    assert seen and seen[0] is not None
    assert not any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree_util.tree_leaves(seen[0]))
    hb_module._FROZEN.clear()
    outside = hb.prepare(system).frozen
    for got, want in zip(jax.tree_util.tree_leaves(seen[0]), jax.tree_util.tree_leaves(outside)):
        np.testing.assert_array_equal(np.asarray(got), np.asarray(want))


@pytest.mark.parametrize("speed_rpm", [1000.0, 13400.0])
def test_nonlinear_start_from_the_quasi_static_state_equals_the_ltv_start(speed_rpm):
    """NLTV without backlash: Newton from the quasi-static state (the default) reaches the solution
    Newton reaches from the LTV solution of the same pair."""
    model = model_with("friction.model=NLTV", "friction.law=arctan")
    w = rpm_to_rad_s(speed_rpm)
    options = dict(harmonics=12, samples=256, tolerance=1e-12)
    default = solve_periodic(model, w, **options)
    ltv = solve_periodic(model.replace(coupling="LTV"), w, **options)
    from_ltv = solve_periodic(model, w, z0=ltv.z, **options)
    assert not np.allclose(ltv.z, from_ltv.z, rtol=0, atol=1e-6)  # the friction model matters here
    np.testing.assert_allclose(default.z, from_ltv.z, rtol=0, atol=1e-8)


@pytest.mark.parametrize("formulation", ["A", "B"])
def test_aft_jump_correction_converges_at_second_order(formulation):
    """The AFT projection of NLTV friction (load shares jump at pair entry and exit) against the
    composite Gauss-Legendre quadrature between the breakpoints (hbgear.engine.quadrature, an
    independent route): sampled plainly it errs at O(1/N); with the jump correction at O(1/N^2),
    and far below the plain projection at the same N."""
    from hbgear.engine.quadrature import fourier_coefficients, mesh_period_rule

    model = model_with("friction.model=NLTV", "friction.law=arctan", "friction.v0_m_per_s=0.5",
                       f"friction.formulation={formulation}")
    system, omega, harmonics = GearSystem(model), rpm_to_rad_s(6000), 8
    rng = np.random.default_rng(11)
    x = rng.normal(size=2 * (2 * harmonics + 1)) * 0.2 * float(system.displacement_scale)
    x[0] += float(system.displacement_scale)

    def sampled_force(hb, s):
        d = fourier.derivative_matrix(harmonics, omega, np)
        xc = x.reshape(2, -1)
        basis = np.concatenate([np.ones((1, s.size)), np.stack([np.cos(np.outer(np.arange(1, harmonics + 1), 2 * np.pi * s)),
                                np.sin(np.outer(np.arange(1, harmonics + 1), 2 * np.pi * s))], axis=1).reshape(2 * harmonics, s.size)])
        return np.asarray(system.force(jnp.asarray(s), jnp.asarray(xc @ basis), jnp.asarray(xc @ d.T @ basis), omega,
                                       "nonlinear", 0.0, jnp))

    s, w = mesh_period_rule(np.asarray(model.breakpoint_candidates(np)), 4 * harmonics)
    c = fourier_coefficients(sampled_force(None, s), s, w, harmonics)
    exact = fourier.coefficients_to_real(c, harmonics)
    errors = {}
    for n in (128, 256, 512):
        hb = HarmonicBalance(2, harmonics, 1, n)
        v = (x.reshape(2, -1) @ fourier.derivative_matrix(harmonics, omega, np).T).ravel()
        corrected = np.asarray(hb._nonlinear(jnp.asarray(x), jnp.asarray(v), 0.0, omega, system)).reshape(2, -1)
        plain = fourier.project(sampled_force(hb, np.arange(n) / n), harmonics)
        errors[n] = (np.abs(plain - exact).max(), np.abs(corrected - exact).max())
    scale = np.abs(exact).max()
    assert errors[512][0] > 1e-4 * scale  # the plain projection does alias
    assert errors[128][1] / errors[512][1] > 10  # O(1/N^2): 16 for N x 4 (plain: ~4)
    assert errors[512][1] < 0.02 * errors[512][0]


@pytest.mark.parametrize("overrides, nu", [
    (["friction.model=NLTV", "friction.law=arctan", "friction.formulation=B"], 1),
    (["boundary.output=reaction", "friction.model=NLTV", "friction.law=arctan"], 2),
    (["boundary.output=torques", "mesh.ste_amplitude_um=[1.0, 0.3]", "mesh.ste_phase_deg=[0.0, 40.0]"], 1),
])
def test_batched_read_outs_equal_each_point_summary(overrides, nu):
    """`read_outs` (a curve's read-outs in batches) gives each point its own summary: no mixing
    of points, the same reaction slot, wind-up and STE velocity per point."""
    from hbgear.gear.solve import PeriodicSolution, read_outs

    model = build_model(load_config(EXAMPLE, overrides))
    h, n = 8 * nu, 64 * nu
    hb = HarmonicBalance(model.ndof, h, nu, n)
    speeds = rpm_to_rad_s(np.array([3000.0, 7000.0, 13400.0]))
    zs = np.array([solve_periodic(model, w, harmonics=h, nu=nu, samples=n).z for w in speeds])
    batch = read_outs(model, speeds, zs, hb)
    assert {len(v) for v in batch.values()} == {3}
    for i, (w, z) in enumerate(zip(speeds, zs)):
        for key, value in PeriodicSolution.from_z(model, w, z, hb).summary().items():
            assert batch[key][i] == pytest.approx(value, rel=1e-11, abs=1e-9), (key, i)
    assert len({round(float(v), 6) for v in batch["dte_rms_um"]}) == 3  # three different points
    # only some read-outs (what frc.csv shows): exactly those values, the others not evaluated
    some = ("dte_mean_um", "dte_p2p_um", "dynamic_factor")
    subset = read_outs(model, speeds, zs, hb, keys=some)
    assert tuple(subset) == some
    for key in some:
        np.testing.assert_array_equal(subset[key], batch[key])
    with pytest.raises(ValueError, match="unknown read-outs"):
        read_outs(model, speeds, zs, hb, keys=("dte_rms_um", "efficiency"))
