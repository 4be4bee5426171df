"""Tests for the Benedict–Kelley / Kelley–Lemanski friction coefficient (hbgear.gear.kelley_lemanski)."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hbgear.gear.kelley_lemanski import (
    KELLEY_C3_SI,
    MU_CAP_DEFAULT,
    ROUGHNESS_LIMIT_UM,
    kelley_lemanski_magnitude,
    roughness_factor,
)

jax.config.update("jax_enable_x64", True)

# Independent conversion factors, written out here and NOT imported from the module.
N_PER_LBF = 4.4482216152605  # exact definition
M_PER_IN = 0.0254  # exact definition
PA_S_PER_CP = 1e-3
UM_PER_UIN = 0.0254


def benedict_kelley_us(w_lb_per_in, eta_cp, vs_in_per_s, ve_in_per_s, s_uin):
    """The 1961 formula, straight from the paper, in its own units (no cap)."""
    c_r = 50.0 / (50.0 - s_uin)
    return 0.0127 * c_r * math.log10(3.17e8 * w_lb_per_in / (eta_cp * vs_in_per_s * ve_in_per_s**2))


# --- (a) hand-computed value in US units == SI function on converted inputs -----------------


def test_hand_computed_us_value_matches_si_function():
    w, eta, vs, ve, s = 1000.0, 10.0, 100.0, 400.0, 20.0  # lb/in, cP, in/s, in/s, µin
    # By hand: arg = 3.17e11 / (10 * 100 * 1.6e5) = 1981.25; C_R = 50/30
    expected = 0.0127 * (50.0 / 30.0) * math.log10(1981.25)
    assert expected == pytest.approx(benedict_kelley_us(w, eta, vs, ve, s), rel=1e-14)
    assert 0.06 < expected < 0.08  # ≈ 0.0698, below the cap, so the clip is not involved

    got = kelley_lemanski_magnitude(
        vs * M_PER_IN,
        ve * M_PER_IN,
        w * N_PER_LBF / M_PER_IN,
        eta * PA_S_PER_CP,
        s * UM_PER_UIN,
    )
    assert abs(float(got) - expected) < 1e-12


def test_si_constant_matches_independent_derivation():
    # C3 in SI: lb/in per N/m = 0.0254/4.448..., cP per Pa s = 1e3, (in/s per m/s)^3 = 0.0254^-3
    c3_si = 3.17e8 * (M_PER_IN / N_PER_LBF) / (1e3 * M_PER_IN**-3)
    assert KELLEY_C3_SI == pytest.approx(c3_si, rel=1e-13)
    # Published SI version (0.02966, PedroTayer/contact_mechanics) is the in/s convention;
    # with ft/s it would be ~51.25.
    assert KELLEY_C3_SI == pytest.approx(0.02966, rel=1e-3)


@pytest.mark.parametrize("s_uin", [0.0, 10.0, 20.0, 40.0])
def test_si_formula_with_si_constant(s_uin):
    w, vs, ve, eta = 3.0e5, 2.0, 15.0, 0.02  # N/m, m/s, m/s, Pa s
    c_r = 50.0 / (50.0 - s_uin)
    expected = 0.0127 * c_r * math.log10(0.0296625 * w / (eta * vs * ve**2))
    got = kelley_lemanski_magnitude(vs, ve, w, eta, s_uin * UM_PER_UIN, mu_cap=1.0)
    assert float(got) == pytest.approx(expected, rel=2e-5)


def test_roughness_factor():
    assert float(roughness_factor(0.0)) == 1.0
    assert float(roughness_factor(25.0 * UM_PER_UIN)) == pytest.approx(2.0, rel=1e-12)
    assert ROUGHNESS_LIMIT_UM == pytest.approx(1.27, rel=1e-12)
    # guarded: finite, >= 1 beyond the singularity and for negative input
    r = roughness_factor(np.array([-1.0, 1.27, 5.0]))
    assert np.all(np.isfinite(r)) and np.all(r >= 1.0) and np.all(r <= 10.0 + 1e-12)


# --- (b) monotonicity --------------------------------------------------------------------------

valid = dict(
    w=st.floats(1e4, 1e6),
    vs=st.floats(0.05, 10.0),
    ve=st.floats(1.0, 40.0),
    eta=st.floats(1e-3, 0.1),
    rq=st.floats(0.0, 1.0),
    factor=st.floats(1.01, 3.0),
)


def _mu(p):
    return float(kelley_lemanski_magnitude(p["vs"], p["ve"], p["w"], p["eta"], p["rq"]))


@settings(max_examples=200, deadline=None)
@given(**valid)
def test_monotonic(w, vs, ve, eta, rq, factor):
    base = dict(vs=vs, ve=ve, w=w, eta=eta, rq=rq)
    mu0 = _mu(base)
    assert 0.0 <= mu0 <= MU_CAP_DEFAULT
    for name, direction in [("vs", -1), ("ve", -1), ("eta", -1), ("w", +1), ("rq", +1)]:
        p = dict(base)
        p[name] = p[name] * factor if name != "rq" else min(p[name] * factor + 0.01, 1.1)
        mu1 = _mu(p)
        assert direction * (mu1 - mu0) >= -1e-15, name
        if 0.0 < mu0 < MU_CAP_DEFAULT and 0.0 < mu1 < MU_CAP_DEFAULT:
            assert direction * (mu1 - mu0) > 0.0, name  # strict away from the clips


# --- (c) typical magnitude ----------------------------------------------------------------------


def test_typical_automotive_magnitude():
    mu = float(kelley_lemanski_magnitude(1.0, 10.0, 2e5, 0.01, 0.5))
    assert 0.02 <= mu <= 0.1  # ≈ 0.079


def test_cap_and_floor_and_degenerate_inputs():
    # at the pitch point the log diverges -> capped
    assert float(kelley_lemanski_magnitude(0.0, 10.0, 2e5, 0.01, 0.5)) == MU_CAP_DEFAULT
    assert float(kelley_lemanski_magnitude(0.0, 10.0, 2e5, 0.01, 0.5, mu_cap=0.2)) == 0.2
    # full-film (argument < 1) -> 0, not negative
    assert float(kelley_lemanski_magnitude(20.0, 50.0, 1e3, 0.1, 0.0)) == 0.0
    # zero / negative load, zero velocities: finite, in range
    out = kelley_lemanski_magnitude(
        np.array([0.0, 1.0, 1.0, -2.0]),
        np.array([0.0, 0.0, 10.0, 10.0]),
        np.array([0.0, 2e5, -1e5, 2e5]),
        0.01,
        0.5,
    )
    assert out.shape == (4,)
    assert np.all(np.isfinite(out)) and np.all((out >= 0) & (out <= MU_CAP_DEFAULT))
    assert out[2] == 0.0  # negative load -> no friction
    # |Vs| is taken: sign of the input does not matter
    assert out[3] == pytest.approx(float(kelley_lemanski_magnitude(2.0, 10.0, 2e5, 0.01, 0.5)))


def test_broadcasting_over_arrays():
    vs = np.linspace(0.1, 5.0, 7)[:, None]
    w = np.array([1e5, 2e5, 4e5])[None, :]
    out = kelley_lemanski_magnitude(vs, 10.0, w, 0.01, 0.5)
    assert out.shape == (7, 3)
    for i in range(7):
        for j in range(3):
            assert out[i, j] == float(kelley_lemanski_magnitude(vs[i, 0], 10.0, w[0, j], 0.01, 0.5))


# --- (d) jax.numpy, jit, grad --------------------------------------------------------------------


def test_jax_matches_numpy_and_jits():
    vs = np.linspace(0.0, 5.0, 11)
    ref = kelley_lemanski_magnitude(vs, 10.0, 2e5, 0.01, 0.5)
    f = jax.jit(lambda v: kelley_lemanski_magnitude(v, 10.0, 2e5, 0.01, 0.5, xp=jnp))
    got = f(jnp.asarray(vs))
    assert got.dtype == jnp.float64
    np.testing.assert_allclose(np.asarray(got), ref, rtol=1e-14, atol=0)


@pytest.mark.parametrize("vs", [0.0, 1e-300, 1e-12, 1e-6, 1e-3])
def test_jax_grad_finite_near_pitch_point(vs):
    def mu(v, ve, w, eta, rq):
        return kelley_lemanski_magnitude(v, ve, w, eta, rq, xp=jnp)

    grads = jax.grad(mu, argnums=(0, 1, 2, 3, 4))(jnp.float64(vs), 10.0, 2e5, 0.01, 0.5)
    assert all(np.isfinite(float(g)) for g in grads)


def test_jax_grad_finite_degenerate_load_and_velocity():
    g = jax.grad(lambda w: kelley_lemanski_magnitude(1.0, 0.0, w, 0.01, 0.5, xp=jnp))(0.0)
    assert np.isfinite(float(g))


def test_jax_grad_matches_analytic_in_unclipped_region():
    vs, ve, w, eta, rq = 1.0, 10.0, 2e5, 0.01, 0.5
    c_r = 50.0 / (50.0 - rq / UM_PER_UIN)
    g = jax.grad(lambda v: kelley_lemanski_magnitude(v, ve, w, eta, rq, xp=jnp))(vs)
    assert float(g) == pytest.approx(-0.0127 * c_r / (math.log(10.0) * vs), rel=1e-12)
    g_ve = jax.grad(lambda v: kelley_lemanski_magnitude(vs, v, w, eta, rq, xp=jnp))(ve)
    assert float(g_ve) == pytest.approx(-2 * 0.0127 * c_r / (math.log(10.0) * ve), rel=1e-12)


# --- (e) the law inside the dynamic model ----------------------------------------------------------

EXAMPLE = __import__("pathlib").Path(__file__).resolve().parent.parent / "examples" / "paper_table1.toml"
KL = ["friction.law='kelley-lemanski'", "friction.viscosity_Pa_s=0.01", "friction.roughness_um=0.5"]


def kl_model(*overrides):
    from hbgear.build import build_model
    from hbgear.config import load_config

    return build_model(load_config(EXAMPLE, [*KL, *overrides]))


def test_model_feeds_the_law_the_load_per_face_width_of_each_pair_and_the_nominal_kinematics():
    """LTV-A: mu_j = sgn(V_s) mu_BK(sigma_j N / b, |V_s|, V_r) with V_s = xi_p W_p - xi_g W_g and
    V_r = xi_p W_p + xi_g W_g, evaluated here with the 1961 formula in US units (independent
    conversions); in double contact each pair carries half the load."""
    model = kl_model("friction.model='LTV'", "boundary.output='torques'", "gear.face_width_mm=20.0")
    omega = 3000.0 * math.pi / 30
    s = np.array([0.1, 0.3, 0.6, 0.95])  # double contact (s < Gamma - 1 = 0.433), then single
    q = np.zeros((1, s.size))
    pf = model.pair_friction(s, q, q, omega)
    wp, wg = omega, omega * model.teeth_pinion / model.teeth_gear
    checked = 0
    for k in range(2):
        for i in range(s.size):
            if pf["sigma"][k, i] == 0:
                continue
            xi_p = model.contact_start_m + model.base_pitch_m * (s[i] + k)
            xi_g = model.line_of_action_m - xi_p
            vs, vr = xi_p * wp - xi_g * wg, xi_p * wp + xi_g * wg
            share = 0.5 if s[i] < model.contact_ratio - 1 else 1.0
            w_lb_in = share * model.normal_load_N / 0.020 * M_PER_IN / N_PER_LBF
            mu = benedict_kelley_us(w_lb_in, 10.0, abs(vs) / M_PER_IN, vr / M_PER_IN, 0.5 / UM_PER_UIN)
            if 0.0 < mu < MU_CAP_DEFAULT:
                assert pf["mu"][k, i] == pytest.approx(math.copysign(mu, vs), rel=1e-12)
                checked += 1
    assert checked >= 4


def test_doubling_face_width_and_load_leaves_mu_and_the_response_shape_unchanged():
    """The law sees the load per unit face width: T_p and b doubled together give the same mu at
    every phase and, the LTV-A equations being linear in N with mu fixed, exactly twice the DTE
    coefficients; T_p doubled alone raises mu by 0.0127 C_R log10(2) wherever it is not clipped."""
    from hbgear.gear.solve import solve_periodic

    base = ["friction.model='LTV'", "boundary.output='torques'"]
    one = kl_model(*base)
    both = kl_model(*base, "load.torque_pinion_Nm=452.0", "gear.face_width_mm=40.0")
    load = kl_model(*base, "load.torque_pinion_Nm=452.0")
    omega = 3000.0 * math.pi / 30
    s = np.linspace(0.0, 1.0, 401, endpoint=False)
    q = np.zeros((1, s.size))
    mu1, mu2, mu3 = (m.pair_friction(s, q, q, omega)["mu"] for m in (one, both, load))
    np.testing.assert_allclose(mu2, mu1, rtol=1e-13, atol=0)
    free = (np.abs(mu1) > 1e-3) & (np.abs(mu3) < MU_CAP_DEFAULT - 1e-12)
    step = 0.0127 * 50.0 / (50.0 - 0.5 / UM_PER_UIN) * math.log10(2.0)  # C_R of 0.5 um
    np.testing.assert_allclose(np.abs(mu3[free]) - np.abs(mu1[free]), step, rtol=1e-10)
    c1, c2, c3 = (solve_periodic(m, omega, harmonics=16).coefficients for m in (one, both, load))
    np.testing.assert_allclose(c2, 2 * c1, rtol=1e-11, atol=1e-11 * np.abs(c1).max())
    assert np.max(np.abs(c3 - 2 * c1)) > 1e-4 * np.abs(c1[0, 1:]).max()


def test_kelley_lemanski_nltv_b_harmonic_balance_matches_time_integration():
    """NLTV-B (the law sees the dynamic load sigma_j F_mesh and the instantaneous V_s, V_r; sgn
    regularised at 5 mm/s), spring boundary, 3000 rpm, zeta 0.05, H = 32: measured HB vs TI
    7.3e-6 (RMS), 1.6e-4 (p2p), 5.9e-4 (dynamic factor), 4.3e-6 (mean net power), the tolerances of
    tests/test_hb.py; the energy identity holds in both to 1e-7 (HB) and 1e-8 (TI)."""
    from hbgear.gear.simulate import simulate
    from hbgear.gear.solve import solve_periodic

    model = kl_model("friction.model='NLTV'", "friction.formulation='B'", "mesh.damping_ratio=0.05",
                     "boundary.damping_ratio=0.1")
    omega = 3000.0 * math.pi / 30
    hb = solve_periodic(model, omega, harmonics=32).summary()
    ti = simulate(model, omega).summary
    assert 700.0 < hb["mean_friction_loss_W"] < 730.0  # mu ~ 0.09: below Coulomb mu0 = 0.1's 958 W
    assert hb["dte_rms_um"] == pytest.approx(ti["dte_rms_um"], rel=5e-5)
    assert hb["dte_p2p_um"] == pytest.approx(ti["dte_p2p_um"], rel=3e-4)
    assert hb["dynamic_factor"] == pytest.approx(ti["dynamic_factor"], rel=1e-3)
    assert hb["mean_power_loss_W"] == pytest.approx(ti["mean_power_loss_W"], rel=2e-5)
    for s, limit in ((hb, 3e-7), (ti, 3e-8)):
        assert abs(s["mean_power_loss_W"] - s["mean_friction_loss_W"] - s["mean_mesh_power_W"]) < limit * s["mean_power_loss_W"]


@pytest.mark.parametrize("roughness", [1.15, 1.2, 1.26])
def test_a_roughness_the_law_would_clip_is_refused(roughness):
    """Above 45 uin (1.143 um) the roughness factor is held at C_R = 10 as a guard: a config
    asking for more would get a silently clipped law, so it is bad input (one line, the key)."""
    from hbgear.build import check_config
    from hbgear.config import load_config
    from hbgear.errors import ConfigError

    cfg = load_config(EXAMPLE, ["friction.law='kelley-lemanski'", f"friction.roughness_um={roughness}"])
    with pytest.raises(ConfigError, match=r"friction.roughness_um = .*<= 1.143 um"):
        check_config(cfg)
    check_config(load_config(EXAMPLE, ["friction.law='kelley-lemanski'", "friction.roughness_um=1.14"]))
