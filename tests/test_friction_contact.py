"""Friction needs a compressive normal load (MODEL.md section 11): the contact gate of the pair
loads, the sign of the friction power, the linear/nonlinear split and the linear equivalents
along solutions, the energy balance with backlash and friction; the model's own checks."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hbgear.build import build_model
from hbgear.config import load_config
from hbgear.errors import ConfigError

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "paper_table1.toml"
BACKLASH = ROOT / "examples" / "backlash.toml"


def model_with(*overrides, example=EXAMPLE):
    return build_model(load_config(example, list(overrides)))


def test_model_rejects_lti_with_formulation_b_or_backlash():
    """GearPairModel itself refuses LTI-B and LTI with backlash (ValueError); the config layer
    keeps its ConfigError naming the key."""
    model = model_with("friction.model=LTI")
    with pytest.raises(ValueError, match="formulation 'B'.*LTI"):
        model.replace(formulation="B")
    with pytest.raises(ValueError, match="backlash.*LTI"):
        model.replace(contact="backlash")
    assert model.replace(coupling="LTV", formulation="B").formulation == "B"
    with pytest.raises(ConfigError, match="friction.formulation"):
        model_with("friction.model=LTI", "friction.formulation=B")
    with pytest.raises(ConfigError, match="mesh.backlash_um"):
        model_with("friction.model=LTI", "mesh.backlash_um=40")


# -- the rule, to the letter -------------------------------------------------------------------------

LAWS = {"none": ["friction.law=none"], "coulomb": ["friction.law=coulomb"],
        "arctan": ["friction.law=arctan"], "kelley-lemanski": ["friction.law=kelley-lemanski"]}
COMBOS = [("LTI", "A", 0.0)] + [(c, f, b) for c in ("LTV", "NLTV") for f in ("A", "B") for b in (0.0, 40.0)]
_MODELS = {}


def model_of(law, coupling, formulation, backlash_um):
    key = (law, coupling, formulation, backlash_um)
    if key not in _MODELS:
        _MODELS[key] = model_with(*LAWS[law], f"friction.model={coupling}", f"friction.formulation={formulation}",
                                  f"mesh.backlash_um={backlash_um}", "mesh.ste_amplitude_um=[0.4]",
                                  "mesh.ste_phase_deg=[30.0]")
    return _MODELS[key]


def expected_loads(model, s, q, qd, omega):
    """MODEL.md section 11 written out: ``N_j`` of every pair slot, shape ``(2, n)``."""
    _, _, _, sigma = model.pair_positions(s)
    load = model.normal_load_N
    eps, _ = model.static_transmission_error(s, model.speeds(omega)[2])
    x = q[0] - eps
    force = model.mesh_force(s, q, qd, omega)
    if model.coupling == "LTI":
        return sigma * load
    if model.contact == "linear":
        return sigma * (load if model.formulation == "A" else np.abs(force))
    b = 0.5 * model.backlash_m
    if model.formulation == "A":
        return sigma * load * (x > b)
    return sigma * (np.where(x > b, np.maximum(force, 0.0), 0.0) + np.where(x < -b, np.maximum(-force, 0.0), 0.0))


def random_states(model, rng, count=400):
    """Phases and states across drive-flank contact, the dead zone and back-flank contact."""
    s = rng.uniform(0.0, 1.0, count)
    delta = rng.uniform(-60e-6, 60e-6, count)
    q = np.stack([delta] + [rng.normal(0.0, 1e-5, count)] * (model.ndof - 1))
    qd = np.stack([rng.normal(0.0, 0.3, count)] + [rng.normal(0.0, 2.0, count)] * (model.ndof - 1))
    return s, q, qd


@pytest.mark.parametrize("coupling, formulation, backlash_um", COMBOS)
@pytest.mark.parametrize("law", sorted(LAWS))
def test_normal_loads_are_the_rule_and_friction_never_produces_power(law, coupling, formulation, backlash_um):
    """``N_j >= 0`` equal to the rule written out here, and ``sum mu_j N_j V_s,j >= 0`` (the
    friction power ``T_fp w_p + T_fg w_g = -sum mu_j N_j V_s,j`` with the speeds ``mu`` sees) at
    random phases and states (3000 rpm and 13400 rpm)."""
    model = model_of(law, coupling, formulation, backlash_um)
    rng = np.random.default_rng(7)
    for rpm in (3000.0, 13400.0):
        omega = rpm * np.pi / 30
        s, q, qd = random_states(model, rng)
        pf = model.pair_friction(s, q, qd, omega)
        expected = expected_loads(model, s, q, qd, omega)
        assert np.all(pf["normal"] >= 0.0)
        np.testing.assert_allclose(pf["normal"], expected, rtol=1e-12, atol=1e-9)
        assert np.all(np.sum(pf["mu"] * pf["normal"] * pf["vs"], axis=0) >= -1e-9)
        t_fp, t_fg = model.friction_torques(s, q, qd, omega)
        wp, wg = model.angular_velocities(qd, omega, nominal=model.coupling != "NLTV")
        np.testing.assert_allclose(t_fp * wp + t_fg * wg, -np.sum(pf["mu"] * pf["normal"] * pf["vs"], axis=0),
                                   rtol=1e-9, atol=1e-6)


def friction_power_at(model, delta_m, omega):
    from hbgear.engine.quadrature import mesh_period_rule

    s, w = mesh_period_rule(model.phase_breakpoints(), 64)
    q = np.stack([np.full_like(s, delta_m), 0.0 * s])
    pf = model.pair_friction(s, q, 0.0 * q, omega)
    power = -np.sum(pf["mu"] * pf["normal"] * pf["vs"], axis=0)
    return float(np.max(power)), float(np.sum(w * power))


def test_back_flank_friction_dissipates_like_the_drive_flank():
    """LTV-B, arctan, 40 um backlash, 3000 rpm, teeth at rest: at delta = -30 um the back flank
    carries ``|F_mesh|`` and friction dissipates what it does at +30 um on the drive flank (mirror
    geometry); before the rule it took ``sigma_j F_mesh < 0`` and produced +1.9 kW (peak), +1019 W
    (mean). In the dead zone (delta = 10 um, here with a closing velocity) nothing."""
    model = model_with("friction.law=arctan", "friction.formulation=B", "mesh.backlash_um=40")
    omega = 3000 * np.pi / 30
    back_peak, back_mean = friction_power_at(model, -30e-6, omega)
    drive_peak, drive_mean = friction_power_at(model, 30e-6, omega)
    assert back_peak <= 0.0 and drive_peak <= 0.0
    assert back_mean == pytest.approx(drive_mean, rel=1e-12)
    assert back_mean == pytest.approx(-1019.0, rel=2e-3)
    s = np.linspace(0.01, 0.99, 50)
    q, qd = np.stack([np.full_like(s, 10e-6), 0 * s]), np.stack([np.full_like(s, 0.5), 0 * s])
    assert np.all(model.pair_friction(s, q, qd, omega)["normal"] == 0.0)
    assert np.all(model.mesh_force(s, q, qd, omega) > 0.0)  # the damping force, which B used to take


# -- the split into linear and nonlinear parts -----------------------------------------------------------

SPLIT = [(law, c, f, b) for law in ("coulomb", "arctan") for (c, f, b) in COMBOS]


@pytest.mark.parametrize("law, coupling, formulation, backlash_um", SPLIT)
def test_split_is_complete_affine_and_declared_right(law, coupling, formulation, backlash_um):
    """linear + nonlinear = all; the linear part is exactly affine in (q, q'); the nonlinear part
    vanishes while the drive flank carries a compressive F_mesh (LTV), so such solutions are those
    of the linear part; ``is_linear`` iff the nonlinear part vanishes at all states; ``Q_nl``
    depends on ``q`` iff declared."""
    from hbgear.gear.system import GearSystem

    model = model_of(law, coupling, formulation, backlash_um)
    system = GearSystem(model)
    omega = 5000 * np.pi / 30
    rng = np.random.default_rng(3)
    s, q, qd = random_states(model, rng, 200)
    force = lambda part, a, b: np.asarray(system.force(s, a, b, omega, part, 0.0, np))  # noqa: E731
    scale = model.normal_load_N
    np.testing.assert_allclose(force("linear", q, qd) + force("nonlinear", q, qd), force("all", q, qd),
                               rtol=1e-12, atol=1e-12 * scale)
    q2, qd2 = random_states(model, rng, 200)[1:]
    zero = 0 * q
    affine_defect = force("linear", q + q2, qd + qd2) - force("linear", q, qd) - force("linear", q2, qd2) + force(
        "linear", zero, zero)
    assert np.max(np.abs(affine_defect)) < 1e-9 * scale
    nonlinear = force("nonlinear", q, qd)
    if model.coupling == "LTV":
        eps, _ = model.static_transmission_error(s, model.speeds(omega)[2])
        b = 0.5 * model.backlash_m if model.contact == "backlash" else -np.inf
        compressive = (q[0] - eps > b) & (model.mesh_force(s, q, qd, omega) > 0)
        assert compressive.sum() > 20 and (~compressive).sum() > 20
        if model.mesh_is_linear:  # (with backlash the dead zone of the mesh force is nonlinear anyway)
            assert np.max(np.abs(nonlinear[:, compressive])) < 1e-9 * scale
            friction_only = formulation == "A"
            assert (np.max(np.abs(nonlinear[:, ~compressive])) < 1e-9 * scale) == friction_only
    if not system.nonlinear_force_uses_displacement:
        np.testing.assert_allclose(force("nonlinear", q + q2, qd), nonlinear, rtol=1e-12, atol=1e-12 * scale)
    else:
        assert np.max(np.abs(force("nonlinear", q + q2, qd) - nonlinear)) > 1e-6 * scale
    assert model.is_linear == (coupling == "LTI" or (coupling, formulation, backlash_um) == ("LTV", "A", 0.0))
    assert model.is_linear == (np.max(np.abs(nonlinear)) == 0.0)


@pytest.mark.parametrize("formulation", ["A", "B"])
@pytest.mark.parametrize("law", ["coulomb", "arctan", "kelley-lemanski"])
def test_declared_speed_structure_holds(law, formulation):
    """Where the system declares the periodic coefficients independent of the speed, the linear
    part's stiffness and damping probed at two speeds agree; where it declares the forcing affine in
    the mesh frequency, the harmonic balance's own check at a third speed accepted it."""
    from hbgear.engine.hb import HarmonicBalance
    from hbgear.gear.system import GearSystem

    for backlash_um in (0.0, 40.0):
        model = model_of(law, "LTV", formulation, backlash_um)
        system = GearSystem(model)
        s = np.linspace(0.003, 0.997, 60)
        unit = np.zeros((model.ndof, s.size))

        def coefficients(omega):
            base = np.asarray(system.force(s, unit, unit, omega, "linear", 0.0, np))
            out = []
            for j in range(model.ndof):
                e = unit.copy()
                e[j] = 1.0
                out.append(base - np.asarray(system.force(s, e, unit, omega, "linear", 0.0, np)))
                out.append(base - np.asarray(system.force(s, unit, e, omega, "linear", 0.0, np)))
            return np.array(out)

        same = np.allclose(coefficients(300.0), coefficients(1400.0), rtol=1e-12, atol=1e-9)
        if system.coefficients_independent_of_parameter:
            assert same
        else:
            assert not same
        prepared = HarmonicBalance(model.ndof, 8, 1, 64).prepare(system)
        assert (prepared.frozen is not None and prepared.frozen.forcing is not None) == system.forcing_affine_in_frequency


# -- linear equivalents along solutions ---------------------------------------------------------------


def test_ltv_b_with_compressive_mesh_force_is_the_linear_solution_and_its_equivalent():
    """LTV-B without backlash is no longer linear (``|F_mesh|``), but where ``F_mesh > 0``
    throughout its solution is that of the affine loads ``sigma_j F_mesh`` (today's LTV-B, one
    linear solve) to rounding, and linear_equivalent returns that linear model, whose exact
    monodromy equals Hill's multipliers of the model itself. Near resonance with little damping
    ``F_mesh`` turns negative: no equivalent, and the solutions differ."""
    from hbgear.engine.floquet import hill_multipliers
    from hbgear.engine.hb import HarmonicBalance
    from hbgear.gear.monodromy import multipliers_linear
    from hbgear.gear.solve import rpm_to_rad_s, solve_periodic
    from hbgear.gear.system import GearSystem, linear_equivalent

    model = model_with("friction.formulation=B", "friction.law=arctan", "mesh.damping_ratio=0.05")
    assert not model.is_linear
    signed = model.replace(normal_loads="signed")
    assert signed.is_linear
    omega = rpm_to_rad_s(3000.0)
    sol = solve_periodic(model, omega, harmonics=32, samples=256)
    reference = solve_periodic(signed, omega, harmonics=32, samples=256)
    np.testing.assert_allclose(sol.coefficients, reference.coefficients, rtol=1e-12,
                               atol=1e-12 * np.abs(reference.coefficients).max())
    equivalent = linear_equivalent(model, sol)
    assert equivalent == signed
    hb = HarmonicBalance(model.ndof, 32, 1, 256)
    hill = np.sort_complex(np.asarray(hill_multipliers(hb, sol.z, omega, GearSystem(model))))
    exact = np.sort_complex(np.asarray(multipliers_linear(equivalent, omega)))
    np.testing.assert_allclose(np.abs(hill), np.abs(exact), atol=1e-6)
    resonant = model.replace(damping_ratio=0.01)
    omega = rpm_to_rad_s(13400.0)
    sol = solve_periodic(resonant, omega, harmonics=32, samples=512)
    assert np.min(resonant.mesh_force(*_nodes(sol), omega)) < 0
    assert linear_equivalent(resonant, sol) is None
    linear = solve_periodic(resonant.replace(normal_loads="signed"), omega, harmonics=32, samples=512)
    assert np.max(np.abs(sol.coefficients - linear.coefficients)) > 1e-3 * np.abs(linear.coefficients).max()


def _nodes(sol):
    f = np.linspace(0.0, 1.0, 2048, endpoint=False)
    q, qd = sol.state_at(f)
    return (f * sol.nu) % 1.0, q, qd


@pytest.mark.parametrize("formulation", ["A", "B"])
def test_linear_equivalent_with_backlash_where_contact_is_kept(formulation):
    """Backlash with friction: a solution that keeps drive-flank contact (9000 rpm) has the linear
    equivalent (contact "linear", loads "signed"), whose exact monodromy equals Hill's multipliers
    of the backlash model; one that loses contact (13400 rpm) has none; NLTV never; a linear model
    is its own."""
    from hbgear.engine.floquet import hill_multipliers
    from hbgear.engine.hb import HarmonicBalance
    from hbgear.gear.monodromy import multipliers_linear
    from hbgear.gear.solve import rpm_to_rad_s, solve_periodic
    from hbgear.gear.system import GearSystem, linear_equivalent

    model = model_with("friction.law=coulomb", "friction.mu0=0.1", f"friction.formulation={formulation}",
                       example=BACKLASH)
    assert linear_equivalent(model) == model.replace(contact="linear", normal_loads="signed")
    omega = rpm_to_rad_s(9000.0)
    sol = solve_periodic(model, omega, harmonics=32, samples=1024)
    equivalent = linear_equivalent(model, sol)
    assert equivalent is not None and equivalent.is_linear
    hb = HarmonicBalance(model.ndof, 32, 1, 1024)
    hill = np.sort(np.abs(np.asarray(hill_multipliers(hb, sol.z, omega, GearSystem(model)))))
    exact = np.sort(np.abs(np.asarray(multipliers_linear(equivalent, omega))))
    # Hill's method on the backlash model carries the AFT's sampling of its Jacobian: 3e-6 here
    # (H = 32, N = 1024), 4e-7 at N = 4096 (H = 48), where it meets Hill on the linear equivalent
    np.testing.assert_allclose(hill, exact, atol=1e-5)
    lost = solve_periodic(model, rpm_to_rad_s(13400.0), harmonics=32, samples=1024)
    assert linear_equivalent(model, lost) is None
    assert linear_equivalent(model.replace(coupling="NLTV"), sol) is None
    plain = model_with()
    assert linear_equivalent(plain, solve_periodic(plain, omega, harmonics=8)) is plain


# -- energy balance with backlash and friction ----------------------------------------------------------


def imbalance(model, sol):
    """``(input - output - friction loss - <F_mesh delta'>)`` relative to the dissipation (friction
    loss plus the viscous mesh loss ``c <delta'^2>``)."""
    s = sol.summary()
    _, qd = sol.state_at(np.linspace(0.0, 1.0, 4096, endpoint=False))
    dissipation = abs(s["mean_friction_loss_W"]) + float(model.mesh_damping_Ns_per_m) * np.mean(qd[0] ** 2)
    return (s["mean_power_loss_W"] - s["mean_friction_loss_W"] - s["mean_mesh_power_W"]) / dissipation


@pytest.mark.parametrize("formulation", ["A", "B"])
@pytest.mark.parametrize("law", sorted(LAWS))
def test_energy_balance_with_backlash_across_contact_loss(law, formulation):
    """examples/backlash.toml with friction, from 15400 rpm (teeth in contact) down to 14800 rpm
    (they separate twice a mesh period), each solution started from the last: net input = friction
    loss + mesh power to 2e-5 of the dissipation at N = 1024 (measured 1e-7 .. 6e-6; without
    friction 6e-6: the dead zone's kinks, O(1/N^2)). Without the located contact jumps the gated
    friction aliases at O(1/N): 5e-4 (Coulomb, A)."""
    from hbgear.gear.solve import rpm_to_rad_s, solve_periodic
    from hbgear.gear.system import linear_equivalent

    extra = ["friction.mu0=0.1"] if law in ("coulomb", "arctan") else []
    model = model_with(*LAWS[law], *extra, f"friction.formulation={formulation}", example=BACKLASH)
    z, contact = None, []
    for rpm in (15400.0, 15200.0, 14800.0):
        sol = solve_periodic(model, rpm_to_rad_s(rpm), harmonics=32, samples=1024, z0=z)
        z = sol.z
        contact.append(linear_equivalent(model, sol) is not None)
        assert abs(imbalance(model, sol)) < 2e-5, (rpm, imbalance(model, sol))
    assert contact == [True, False, False]


def test_frequency_response_continues_through_contact_loss_with_balanced_energy():
    """Pseudo-arclength continuation (as ``hbgear frc``) of backlash.toml with Coulomb friction,
    formulation B, from 15300 to 15260 rpm: the teeth start to separate on the way; every point
    balances the energy to 1e-6 of the dissipation."""
    from hbgear.engine.continuation import Status, continuation, sweep_method
    from hbgear.engine.hb import HarmonicBalance, residual_functions
    from hbgear.gear.solve import PeriodicSolution, read_outs, rpm_to_rad_s, solve_periodic
    from hbgear.gear.system import GearSystem, linear_equivalent

    model = model_with("friction.law=coulomb", "friction.mu0=0.1", "friction.formulation=B", example=BACKLASH)
    hb = HarmonicBalance(model.ndof, 32, 1, 1024)
    rj, r, fixed = residual_functions(hb, GearSystem(model))
    a, b = rpm_to_rad_s(15300.0), rpm_to_rad_s(15260.0)
    start = solve_periodic(model, a, harmonics=32, samples=1024)
    branch = continuation(rj, r, start.z, a, b, sweep_method(a, b, None), max_points=400, tolerance=1e-9,
                          progress=False, args=fixed)
    assert branch.status == Status.SUCCESS, branch.message
    keeps = [linear_equivalent(model, PeriodicSolution.from_z(model, p, z, hb)) is not None
             for p, z in zip(branch.p, branch.z)]
    assert keeps[0] and not keeps[-1]
    s = read_outs(model, branch.p, branch.z, hb)
    imbalance_W = s["mean_power_loss_W"] - s["mean_friction_loss_W"] - s["mean_mesh_power_W"]
    assert np.max(np.abs(imbalance_W) / s["mean_friction_loss_W"]) < 1e-6


def test_kelley_lemanski_sign_stays_finite_when_its_regularisation_is_traced():
    """Under jit the law's fields are traced, so ``v_reg = 0`` cannot be told apart by Python: the
    sign must still be ``sgn(V_s)`` with a finite derivative (it was ``atan(V_s/0)``: NaN at
    ``V_s = 0`` and in every derivative, which broke LTV's gated friction in the compiled residual)."""
    import jax
    import jax.numpy as jnp

    from hbgear.gear.friction import KelleyLemanski

    vs = jnp.array([-2.0, 0.0, 3.0])
    law = KelleyLemanski(0.01, 0.5)
    mu = jax.jit(lambda lw, v: lw.mu(v, 10.0 + 0 * v, 1e5 + 0 * v, jnp))
    np.testing.assert_array_equal(np.sign(np.asarray(mu(law, vs))), [-1.0, 0.0, 1.0])
    np.testing.assert_allclose(np.asarray(mu(law, vs)), law.mu(np.asarray(vs), 10.0, 1e5), rtol=1e-12)
    tangent = jax.jvp(lambda v: mu(law, v), (vs,), (jnp.ones(3),))[1]
    assert np.all(np.isfinite(np.asarray(tangent)))
    smooth = law.regularized(0.01)
    np.testing.assert_allclose(np.asarray(mu(smooth, vs)), smooth.mu(np.asarray(vs), 10.0, 1e5), rtol=1e-12)
