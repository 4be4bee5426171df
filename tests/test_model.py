"""GearPairModel physics: stiffness spectrum, friction power, sliding direction, numpy == JAX."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hbgear.build import build_model
from hbgear.config import parse_config
from hbgear.engine.quadrature import fourier_coefficients, mesh_period_rule

jax.config.update("jax_enable_x64", True)

BASE = {
    "gear": dict(teeth_pinion=25, teeth_gear=31, module_mm=3.175, contact_ratio=1.433,
                 inertia_pinion_kgm2=1.0594e-3, inertia_gear_kgm2=2.5047e-3),
    "mesh": dict(k_max_MN_per_m=720.0, k_mean_MN_per_m=568.0, damping_ratio=0.01),
    "load": dict(torque_pinion_Nm=226.0),
}
LAWS = {
    "coulomb": {"law": "coulomb", "mu0": 0.1},
    "arctan": {"law": "arctan", "mu0": 0.1, "v0_m_per_s": 0.01},
    "kelley-lemanski": {"law": "kelley-lemanski"},
    "none": {"law": "none"},
}


def model_for(law="coulomb", coupling="LTV", formulation="A", output="spring", **mesh):
    data = {k: dict(v) for k, v in BASE.items()}
    data["mesh"].update(mesh)
    data["friction"] = dict(LAWS[law], model=coupling, formulation=formulation)
    data["boundary"] = {"output": output}
    return build_model(parse_config(data))


def test_stiffness_fourier_coefficients():
    model = model_for()
    ta = model.contact_ratio - 1.0
    dk = model.k_max_N_per_m - model.k_min_N_per_m
    orders = 12
    s, w = mesh_period_rule(model.phase_breakpoints(), orders)
    coef = fourier_coefficients(model.mesh_stiffness(s), s, w, orders)
    # closed form (MODEL.md section 2): f_n = (a_n - i b_n)/2
    n = np.arange(1, orders + 1)
    a = dk * np.sin(2 * np.pi * n * ta) / (n * np.pi)
    b = dk * (1 - np.cos(2 * np.pi * n * ta)) / (n * np.pi)
    assert coef[0].real == pytest.approx(model.k_mean_N_per_m, rel=1e-13)
    np.testing.assert_allclose(coef[1:], (a - 1j * b) / 2, atol=1e-9 * dk)
    # against an FFT of a finely sampled pulse (error O(1/N))
    samples = 1 << 16
    fft = np.fft.rfft(model.mesh_stiffness(np.arange(samples) / samples)) / samples
    np.testing.assert_allclose(coef, fft[: orders + 1], atol=2 * dk / samples * orders)


def friction_power(model, s, q, qd, wp):
    """T_fp (Omega_p + theta_p') + T_fg (Omega_g + theta_g') with the speeds friction sees."""
    t_fp, t_fg = model.friction_torques(s, q, qd, wp)
    p, g = model.angular_velocities(qd, wp, nominal=model.coupling != "NLTV")
    return t_fp * p + t_fg * g, model.pair_friction(s, q, qd, wp)


MODELS = [
    (law, coupling, form)
    for law in LAWS
    for coupling in ("LTI", "LTV", "NLTV")
    for form in ("A", "B")
    if not (coupling == "LTI" and form == "B")
]
_BUILT = {key: model_for(*key) for key in MODELS}


@settings(max_examples=60, deadline=None)
@given(
    key=st.sampled_from(MODELS),
    s=st.floats(0.0, 0.999999),
    dfac=st.floats(0.5, 1.5),
    ddot=st.floats(-0.5, 0.5),
    udot=st.floats(-2.0, 2.0),
    rpm=st.floats(10.0, 20000.0),
)
def test_friction_power_dissipative(key, s, dfac, ddot, udot, rpm):
    model = _BUILT[key]
    wp = rpm * math.pi / 30
    s = np.asarray([s])
    delta = dfac * model.normal_load_N / model.mesh_stiffness(s)
    q = np.stack([delta, np.zeros(1)])
    qd = np.stack([np.full(1, ddot * 1e-3), np.full(1, udot)])
    assert np.all(model.mesh_force(s, q, qd, wp) > 0)  # teeth loaded: N_j >= 0 for formulation B
    power, pf = friction_power(model, s, q, qd, wp)
    assert power[0] <= 1e-9 * (1 + abs(power[0]))
    # and it equals -sum |mu_j| N_j |Vs_j|
    expected = -np.sum(np.abs(pf["mu"]) * pf["normal"] * np.abs(pf["vs"]), axis=0)
    assert power[0] == pytest.approx(expected[0], rel=1e-9, abs=1e-9)


def test_sliding_velocity_sign():
    model = model_for()
    wp = 3000 * math.pi / 30
    s = np.linspace(0.0005, 0.9995, 2001)
    q = np.zeros((2, s.size))
    pf = model.pair_friction(s, q, q, wp)
    xp = model.pitch_point_m
    contact = pf["sigma"] > 0
    before = contact & (pf["xi_p"] < xp - 1e-9)
    after = contact & (pf["xi_p"] > xp + 1e-9)
    assert before.any() and after.any()
    assert np.all(pf["vs"][before] < 0)  # approach
    assert np.all(pf["vs"][after] > 0)  # recess
    wg = wp * 25 / 31
    np.testing.assert_allclose(pf["vs"], (pf["xi_p"] - xp) * (wp + wg), atol=1e-12)
    # Coulomb mu changes sign exactly at the pitch crossing phase, a breakpoint
    assert np.all(pf["mu"][before] == -0.1) and np.all(pf["mu"][after] == 0.1)


@pytest.mark.parametrize(
    "key", [("arctan", "NLTV", "B"), ("kelley-lemanski", "NLTV", "A"), ("coulomb", "LTV", "B"),
            ("coulomb", "LTI", "A")],
)
@pytest.mark.parametrize("output", ["spring", "torques"])
def test_generalized_force_numpy_equals_jax(key, output):
    if output == "torques" and key[1] == "NLTV":
        pytest.skip("NLTV needs both gear speeds")
    model = model_for(*key, output=output, ste_amplitude_um=[0.5, 0.2], ste_phase_deg=[10.0, 40.0])
    rng = np.random.default_rng(1)
    s = rng.uniform(0, 1, 64)
    n = model.ndof
    q = np.stack([rng.uniform(0.5, 1.5, 64) * 1e-5] + [rng.normal(0, 1e-5, 64)] * (n - 1))
    qd = rng.normal(0, 0.05, (n, 64))
    wp = 5000 * math.pi / 30
    f_np = model.generalized_force(s, q, qd, wp, u_static=2.0)
    f_jx = model.generalized_force(jnp.asarray(s), jnp.asarray(q), jnp.asarray(qd), wp, u_static=2.0, xp=jnp)
    np.testing.assert_allclose(np.asarray(f_jx), f_np, rtol=1e-12, atol=1e-9)
    for part in ("linear", "nonlinear"):
        a = model.generalized_force(s, q, qd, wp, part=part, u_static=2.0)
        b = model.generalized_force(jnp.asarray(s), jnp.asarray(q), jnp.asarray(qd), wp, part=part, u_static=2.0, xp=jnp)
        np.testing.assert_allclose(np.asarray(b), a, rtol=1e-12, atol=1e-9)
    # the split is complete
    lin = model.generalized_force(s, q, qd, wp, part="linear", u_static=2.0)
    non = model.generalized_force(s, q, qd, wp, part="nonlinear", u_static=2.0)
    np.testing.assert_allclose(lin + non, f_np, rtol=1e-12, atol=1e-9)


@pytest.mark.parametrize("coupling", ["LTI", "LTV", "NLTV"])
@pytest.mark.parametrize("zeta", [0.001, 0.05])
def test_mesh_damping_from_the_raw_config_numbers(coupling, zeta):
    """``c = 2 zeta sqrt(k_mean m_e)`` (MODEL.md section 2) with ``m_e = 1/(R_bp^2/J_p + R_bg^2/J_g)``
    from the module, tooth numbers, pressure angle and inertias; read off the mesh force."""
    model = model_for(coupling=coupling, law="none", damping_ratio=zeta)
    module_m, phi = 3.175e-3, math.radians(20.0)  # BASE and the default pressure angle
    rbp, rbg = module_m * 25 * math.cos(phi) / 2, module_m * 31 * math.cos(phi) / 2
    m_e = 1.0 / (rbp**2 / 1.0594e-3 + rbg**2 / 2.5047e-3)
    assert m_e == pytest.approx(0.4615, abs=5e-4)  # MODEL.md section 1
    c = 2 * zeta * math.sqrt(568e6 * m_e)
    assert float(model.mesh_damping_Ns_per_m) == pytest.approx(c, rel=1e-12)
    # the damping the equations use: dF_mesh/d(delta') at phases in double and single contact
    s = np.array([0.1, 0.3, 0.6, 0.9])
    omega = 1000.0 * math.pi / 30
    q = np.zeros((model.ndof, s.size))
    qd = np.zeros_like(q)
    qd[0] = 1.0
    slope = np.asarray(model.mesh_force(s, q, qd, omega)) - np.asarray(model.mesh_force(s, q, 0 * qd, omega))
    np.testing.assert_allclose(slope, c, rtol=1e-12)


@pytest.mark.parametrize(
    "overrides",
    [
        ["friction.model=NLTV", "friction.law=arctan"],
        ["friction.model=NLTV", "friction.law=arctan", "friction.formulation='B'"],
        ["friction.law=arctan", "friction.v0_m_per_s=0.001"],
        ["friction.model=NLTV"],  # coulomb, regularised to arctan
        [],  # LTV coulomb
        ["friction.law=coulomb", "friction.formulation='B'", "gear.contact_ratio=1.7"],
    ],
)
def test_static_windup_closed_form_equals_the_quadrature(overrides):
    """The wind-up's mean friction force in closed form (sgn / atan laws) equals the graded
    quadrature of the full generalised force, with its derivative in the speed."""
    from pathlib import Path

    from hbgear.config import load_config

    example = Path(__file__).resolve().parents[1] / "examples" / "paper_table1.toml"
    model = build_model(load_config(example, overrides))
    assert model._mean_static_friction_force(1000.0) is not None

    def by_quadrature(omega):
        s, w = mesh_period_rule(model.breakpoint_candidates(jnp), 8, jnp)
        q = jnp.stack([model.normal_load_N / model.mesh_stiffness(s, jnp), 0.0 * s])
        force = model.generalized_force(s, q, 0.0 * q, omega, "all", 0.0, 0.0, jnp)
        return jnp.sum(w * force[1]) - model.torque_pinion_Nm / model.base_radius_pinion_m

    def closed(omega):
        return model._mean_static_friction_force(omega, jnp)

    friction_scale = model.friction.mu0 * model.normal_load_N * model.line_of_action_m / model.base_radius_gear_m
    for rpm in (50.0, 3000.0, 13400.0, 21000.0):
        w = rpm * 2 * math.pi / 60
        (got, got_dw), (want, want_dw) = jax.jvp(closed, (w,), (1.0,)), jax.jvp(by_quadrature, (w,), (1.0,))
        assert abs(float(want)) > 1e-3 * friction_scale  # friction does load the spring
        assert abs(float(got - want)) <= 1e-12 * friction_scale
        assert abs(float(got_dw - want_dw)) <= 1e-10 * friction_scale / w
    u_static = model.static_state(3000 * 2 * math.pi / 60)[1]
    expected = (model.torque_pinion_Nm / model.base_radius_pinion_m + float(closed(3000 * 2 * math.pi / 60)))
    assert float(u_static) == pytest.approx(expected / model.spring_stiffness_N_per_m, rel=1e-15)
    assert model.static_windup(3000 * 2 * math.pi / 60) == u_static  # u_s alone: the same value
    # several speeds at once (a curve's read-outs): each its own wind-up, as by the quadrature
    speeds = np.array([50.0, 3000.0, 13400.0, 21000.0]) * 2 * math.pi / 60
    want = [(model.torque_pinion_Nm / model.base_radius_pinion_m + float(by_quadrature(w)))
            / model.spring_stiffness_N_per_m for w in speeds]
    np.testing.assert_allclose(model.static_windup(speeds), want, rtol=0,
                               atol=1e-12 * friction_scale / model.spring_stiffness_N_per_m)


def test_static_windup_of_several_speeds_by_quadrature():
    """A law without a closed form (Kelley-Lemanski): an array of speeds gives each speed's own
    quadrature wind-up, in the array's shape."""
    from pathlib import Path

    from hbgear.config import load_config

    example = Path(__file__).resolve().parents[1] / "examples" / "paper_table1.toml"
    model = build_model(load_config(example, ["friction.law=kelley-lemanski"]))
    assert model._mean_static_friction_force(1000.0) is None
    speeds = np.array([[1000.0, 3000.0], [7000.0, 13400.0]]) * 2 * math.pi / 60
    got = np.asarray(model.static_windup(speeds))
    assert got.shape == speeds.shape
    want = [float(model.static_state(w)[1]) for w in speeds.ravel()]
    np.testing.assert_array_equal(got.ravel(), want)
    assert len(set(want)) == 4  # the speed matters: no point took another's value
