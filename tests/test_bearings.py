"""The gear pair on bearings and shafts (MODEL.md section 10): each check an independent route.

- the rigid-bearing limit: stiff bearings converge to the 2-DOF DTE at first order in the bearing
  compliance (the rigid model itself is the derivation's, ``test_equations_of_motion.py``);
- without friction the OLOA bearing forces are exactly zero;
- the means of the bearing forces from the period means of the translation equations;
- the energy identity with the bearing and shaft damper losses;
- harmonic balance against time integration;
- Hill's method against the variational monodromy;
- the natural frequencies against an eigen-analysis of ``M`` and ``K`` written here in the
  physical coordinates (``theta``, ``y``, ``x``);
- the config's checks of ``[bearings]`` / ``[shafts]`` (exit 2, one line).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from hbgear import build_model, load_config, natural_frequencies
from hbgear.config import parse_config, read_toml
from hbgear.errors import ConfigError
from hbgear.gear.solve import rpm_to_rad_s, solve_periodic

# a failed trace of the compiled corrector falls back to the Python one with a warning: here an error
pytestmark = pytest.mark.filterwarnings("error:jit_step:RuntimeWarning")

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "bearings.toml"
SHAFTS = dict(drive_inertia_kgm2=5e-3, load_inertia_kgm2=1e-2, drive_stiffness_Nm_per_rad=2e5,
              load_stiffness_Nm_per_rad=3e5, damping_ratio=0.02)


def model_with(*overrides, shafts=False, bearings=True, shaft_damping_ratio=None):
    data = read_toml(EXAMPLE)
    if shafts:
        data["shafts"] = dict(SHAFTS)
        if shaft_damping_ratio is not None:
            data["shafts"]["damping_ratio"] = shaft_damping_ratio
    if not bearings:
        del data["bearings"]
    return build_model(parse_config(data, overrides))


def test_layouts_are_configurations_of_one_assembly():
    """2, 6 and 8 DOF (and the torques boundary's elimination) from the same code: coordinates."""
    assert model_with(bearings=False).layout.coordinates == ("delta", "u")
    assert model_with().layout.coordinates == ("delta", "u", "y_p", "x_p", "y_g", "x_g")
    assert model_with(shafts=True).ndof == 8
    assert model_with("boundary.output=torques", shafts=True).layout.coordinates == (
        "delta", "y_p", "x_p", "y_g", "x_g", "t_d", "t_l")
    m = model_with()
    assert m.bearings.mass_pinion_kg == pytest.approx(2 * 1.0594e-3 / (3.175e-3 * 25 / 2) ** 2, rel=1e-12)
    k, c = m.bearings.k_pinion_oloa_N_per_m, m.bearings.dampings[1]
    assert c == pytest.approx(2 * 0.02 * math.sqrt(k * m.bearings.mass_pinion_kg), rel=1e-14)


@pytest.mark.parametrize("boundary", ["torques", "spring"])
def test_stiff_bearings_converge_to_the_2dof_dte(boundary):
    """Bearing stiffness 1e13 .. 1e16 N/m (LTV-A, 5000 rpm): the DTE coefficients tend to the 2-DOF
    model's with the error ~ 1/k (first order in the compliance: each decade gains one), below
    1e-6 relative at 1e16 N/m."""
    omega = rpm_to_rad_s(5000.0)
    rigid = model_with(f"boundary.output={boundary}", bearings=False)
    reference = solve_periodic(rigid, omega, harmonics=16).coefficients[0]
    errors = []
    for k_mn in (1e7, 1e8, 1e9, 1e10):
        m = model_with(f"boundary.output={boundary}", f"bearings.pinion_stiffness_MN_per_m={k_mn}",
                       f"bearings.gear_stiffness_MN_per_m={k_mn}")
        dte = solve_periodic(m, omega, harmonics=16).coefficients[0]
        errors.append(np.max(np.abs(dte - reference)) / np.max(np.abs(reference)))
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    assert np.all((ratios > 7.0) & (ratios < 13.0)), errors
    assert errors[-1] < 1e-6, errors


@pytest.mark.parametrize("overrides", [("friction.law=none",), ("friction.mu0=0.0",),
                                       ("friction.law=none", "friction.model=NLTV", "friction.formulation=B")])
def test_no_friction_no_oloa_bearing_forces(overrides):
    """mu = 0: nothing acts across the line of action, the OLOA forces are exactly zero; the LOA ones not."""
    sol = solve_periodic(model_with(*overrides), rpm_to_rad_s(6000.0), harmonics=16)
    s = sol.summary()
    for end in ("pinion", "gear"):
        for stat in ("rms", "p2p", "mean"):
            assert s[f"bearing_force_{end}_oloa_{stat}_N"] == 0.0
        assert s[f"bearing_force_{end}_loa_rms_N"] > 10.0
    assert not np.any(sol.coefficients[[3, 5]])


@pytest.mark.parametrize("overrides", [(), ("friction.model=NLTV", "friction.formulation=B"),
                                       ("boundary.output=reaction",)])
def test_mean_bearing_forces_are_the_mean_mesh_and_friction_forces(overrides):
    """Period means of the translation equations: ``k <y_g> = <F_mesh>`` (``-`` for the pinion) and
    ``k <x_g> = <F_fg>``; the pinion equation's mean gives ``<F_mesh> = N + <T_fp>/R_bp`` (the
    static mesh force ``N = T_p/R_bp`` without friction). Means from the model's mesh and friction
    functions at the read-out quadrature. The bearing equations are linear, so their means hold to
    the solver's tolerance; the pinion equation's holds to 1e-9 for LTV and, for NLTV, to the
    difference between the read-out quadrature and the AFT samples the solution satisfies its
    friction at (the O(1/N^2) of the energy identity: 1.1e-6 measured at N = 1024, H = 24)."""
    m = model_with(*overrides)
    pinion_tol = 1e-9 if m.coupling != "NLTV" else 3e-6
    omega = rpm_to_rad_s(7000.0)
    sol = solve_periodic(m, omega, harmonics=24)
    s = sol.summary()
    _, phases, w = sol.quadrature()
    q, qd = sol.state_at(sol.quadrature()[0])
    mesh = float(np.sum(w * m.mesh_force(phases, q, qd, omega)))
    t_fp, _, _, f_fg = (np.asarray(a) for a in m.friction_actions(phases, q, qd, omega))
    assert s["bearing_force_gear_loa_mean_N"] == pytest.approx(mesh, rel=1e-9)
    assert s["bearing_force_pinion_loa_mean_N"] == pytest.approx(-mesh, rel=1e-9)
    assert mesh == pytest.approx(m.normal_load_N + float(np.sum(w * t_fp)) / m.base_radius_pinion_m, rel=pinion_tol)
    friction = float(np.sum(w * f_fg))
    assert abs(friction) > 1.0
    # NLTV: the mean friction force (a small difference of +-mu0 N across the pitch point) carries the
    # quadrature's error on the regularised sgn's steep ramps: 2e-2 N of mu0 N = 606 N measured
    tol = dict(rel=1e-8) if m.coupling != "NLTV" else dict(abs=1e-4 * 0.1 * m.normal_load_N)
    assert s["bearing_force_gear_oloa_mean_N"] == pytest.approx(friction, **tol)
    assert s["bearing_force_pinion_oloa_mean_N"] == pytest.approx(-friction, **tol)


def _imbalance(model, rpm, samples=1024):
    s = solve_periodic(model, rpm_to_rad_s(rpm), harmonics=32, samples=samples).summary()
    losses = s["mean_friction_loss_W"] + s["mean_mesh_power_W"] + s["mean_bearing_loss_W"] + s.get(
        "mean_shaft_loss_W", 0.0)
    assert s["mean_bearing_loss_W"] > 1e-3 * s["mean_power_loss_W"]  # the term is exercised
    return abs(s["mean_power_loss_W"] - losses) / s["mean_power_loss_W"]


@pytest.mark.parametrize("overrides, shafts, limit", [
    ((), False, 1e-12), (("friction.formulation=B",), True, 1e-12),
    (("friction.model=NLTV",), False, 1e-6), (("friction.model=NLTV", "friction.formulation=B"), True, 1e-6),
], ids=["LTV-A-6dof", "LTV-B-8dof", "NLTV-A-6dof", "NLTV-B-8dof"])
def test_energy_identity_with_bearing_losses(overrides, shafts, limit):
    """Net input = friction loss + <F_mesh delta'> + bearing (+ shaft) damper losses, 5000 rpm near
    the bearing modes (H = 32, N = 1024): linear couplings to rounding, NLTV to the AFT's O(1/N^2)
    (as the 2-DOF model's ~1e-7)."""
    assert _imbalance(model_with("boundary.damping_ratio=0.1", *overrides, shafts=shafts), 5000.0) < limit


@pytest.mark.parametrize("overrides, shafts", [((), False), (("friction.model=NLTV", "friction.law=arctan"), True)],
                         ids=["LTV-6dof", "NLTV-8dof"])
def test_harmonic_balance_against_time_integration(overrides, shafts):
    """HB (H = 48) against time integration to a steady state (reaction boundary): DTE and the four
    bearing forces' RMS within 0.1 %. The shafts damped at 10 % (not the 2 % of :data:`SHAFTS`):
    their slowest mode then settles in ~250 mesh cycles instead of ~970 (18 s against 76 s of
    integration; the agreement, 7e-5 and 5e-5 at worst, is the same)."""
    from hbgear.gear.simulate import simulate

    m = model_with("boundary.output=reaction", *overrides, shafts=shafts,
                   shaft_damping_ratio=0.1 if shafts else None)
    omega = rpm_to_rad_s(4500.0)
    hb = solve_periodic(m, omega, harmonics=48).summary()
    ti = simulate(m, omega, rtol=1e-10, steady_tolerance=1e-7, max_cycles=3000).summary
    for key in ("dte_rms_um", "bearing_force_pinion_loa_rms_N", "bearing_force_pinion_oloa_rms_N",
                "bearing_force_gear_loa_rms_N", "bearing_force_gear_oloa_rms_N"):
        assert ti[key] == pytest.approx(hb[key], rel=1e-3), key


def test_hill_against_variational_monodromy_on_bearings():
    """NLTV (arctan) on 6 DOF at 6000 rpm: Hill's multipliers (H = 32, N = 1024) against the
    eigenvalues of the variational monodromy along the same solution."""
    from hbgear.engine import floquet
    from hbgear.engine.hb import HarmonicBalance
    from hbgear.gear import monodromy
    from hbgear.gear.system import GearSystem

    m = model_with("friction.model=NLTV", "friction.law=arctan", "boundary.damping_ratio=0.1")
    w = rpm_to_rad_s(6000.0)
    sol = solve_periodic(m, w, harmonics=32, samples=1024)
    exact = np.linalg.eigvals(monodromy.monodromy_variational(m, sol, w))
    hill = floquet.hill_multipliers(HarmonicBalance(m.ndof, 32, 1, 1024), sol.z, w, GearSystem(m))
    assert len(hill) == len(exact) == 12
    for x in exact:
        assert np.min(np.abs(hill - x)) < 1e-4, (x, hill)


def _physical_matrices(m, shafts: bool):
    """``M``, ``K`` in ``(theta_p, theta_g, y_p, x_p, y_g, x_g[, theta_d, theta_l])``, written from
    MODEL.md section 10: ``V = 1/2 k_mean delta^2 + 1/2 k_b theta_out^2 + bearings + shafts``."""
    rbp, rbg, b = m.base_radius_pinion_m, m.base_radius_gear_m, m.bearings
    n = 8 if shafts else 6
    mass = np.diag([m.inertia_pinion_kgm2, m.inertia_gear_kgm2, b.mass_pinion_kg, b.mass_pinion_kg, b.mass_gear_kg,
                    b.mass_gear_kg] + ([SHAFTS["drive_inertia_kgm2"], SHAFTS["load_inertia_kgm2"]] if shafts else []))
    g = np.zeros(n)
    g[[0, 1, 2, 4]] = rbp, -rbg, 1.0, -1.0  # delta = R_bp theta_p - R_bg theta_g + y_p - y_g
    k = m.k_mean_N_per_m * np.outer(g, g)
    k[2, 2] += b.k_pinion_loa_N_per_m
    k[3, 3] += b.k_pinion_oloa_N_per_m
    k[4, 4] += b.k_gear_loa_N_per_m
    k[5, 5] += b.k_gear_oloa_N_per_m
    out = 7 if shafts else 1
    k[out, out] += m.k_mean_N_per_m * rbg**2 / 5e5  # the soft output spring on the output body
    if shafts:
        for a, bb, kt in ((6, 0, SHAFTS["drive_stiffness_Nm_per_rad"]), (1, 7, SHAFTS["load_stiffness_Nm_per_rad"])):
            e = np.zeros(n)
            e[a], e[bb] = 1.0, -1.0
            k += kt * np.outer(e, e)
    return mass, k


@pytest.mark.parametrize("shafts", [False, True])
def test_natural_frequencies_against_a_separate_eigen_analysis(shafts):
    """``hbgear.natural_frequencies`` (``K`` from the model's own force, ``M = P^T M_r P``) against
    ``K v = w^2 M v`` of the physical coordinates written out here."""
    from scipy.linalg import eigh

    m = model_with(shafts=shafts)
    mass, k = _physical_matrices(m, shafts)
    expected = np.sqrt(eigh(k, mass, eigvals_only=True)) / (2 * math.pi)
    modes = natural_frequencies(m)
    # eigenvalues w^2 to 1e-9, the soft output mode's (1e-7 of the largest) to rounding of the pencil,
    # eps w_max^2 (1.3e-9 relative measured on its frequency)
    np.testing.assert_allclose(modes.frequencies_hz**2, expected**2, rtol=1e-9, atol=1e-13 * expected.max() ** 2)
    assert modes.names.count("mesh") == 1 and "pinion OLOA bearing" in modes.names
    # the 2-DOF model's mesh mode is MODEL.md's primary resonance at ~13,400 rpm
    rigid = natural_frequencies(model_with(bearings=False))
    assert rigid.resonance_speeds_rpm(25, [1])[rigid.names.index("mesh"), 0] == pytest.approx(13400.0, rel=1e-3)


@pytest.mark.parametrize("key, value, needle", [
    ("bearings.pinion_stiffness_MN_per_m", -5.0, "positive stiffness"),
    ("bearings.gear_oloa_stiffness_MN_per_m", 0.0, "positive stiffness"),
    ("bearings.damping_ratio", 1.5, "bearings.damping_ratio"),
    ("bearings.mass_gear_kg", -1.0, "positive mass"),
    ("bearings.stiffness_MN_per_m", 500.0, "not a known key"),
    ("shafts.drive_inertia_kgm2", 0.0, "positive inertia"),
    ("shafts.spline", 1.0, "not a known key"),
])
def test_bad_bearing_and_shaft_input_is_a_config_error(key, value, needle):
    data = read_toml(EXAMPLE)
    data["shafts"] = dict(SHAFTS)
    with pytest.raises(ConfigError) as err:
        parse_config(data, [f"{key}={value}"])
    assert needle in str(err.value) and "\n" not in str(err.value)


def test_missing_bearing_stiffness_and_shaft_keys():
    data = read_toml(EXAMPLE)
    del data["bearings"]["gear_stiffness_MN_per_m"]
    with pytest.raises(ConfigError, match="bearings.gear_stiffness_MN_per_m"):
        parse_config(data)
    data["bearings"] |= {"gear_loa_stiffness_MN_per_m": 300.0, "gear_oloa_stiffness_MN_per_m": 200.0}
    b = build_model(parse_config(data)).bearings
    assert (b.k_gear_loa_N_per_m, b.k_gear_oloa_N_per_m) == (3e8, 2e8)
    data["shafts"] = {k: v for k, v in SHAFTS.items() if k != "load_stiffness_Nm_per_rad"}
    with pytest.raises(ConfigError, match="shafts.load_stiffness_Nm_per_rad"):
        parse_config(data)


def test_config_round_trip_with_shafts():
    data = read_toml(EXAMPLE)
    data["shafts"] = dict(SHAFTS)
    cfg = parse_config(data)
    again = parse_config(cfg.to_dict())
    assert again.bearings == cfg.bearings and again.shafts == cfg.shafts
    assert load_config(EXAMPLE).bearings.pinion_stiffness_N_per_m == 5e8


def test_frc_command_on_bearings_writes_the_bearing_columns(tmp_path):
    """``hbgear frc`` on bearings: frc.csv gains the bearing-force RMS columns, with the values of
    the solution's own summary at a curve point, and bearing_forces.png / modes.json are written."""
    import csv

    from hbgear.cli import main

    out = tmp_path / "frc"
    status = main(["frc", str(EXAMPLE), "--set", "sweep.speed_rpm_start=9000.0", "--set", "sweep.speed_rpm_stop=9500.0",
                   "--no-stability", "--no-period-doubling", "--no-progress", "--out", str(out)])
    assert status == 0
    rows = list(csv.DictReader((out / "frc.csv").open()))
    names = [f"bearing_force_{g}_{d}_rms_N" for g in ("pinion", "gear") for d in ("loa", "oloa")]
    assert set(names) <= set(rows[0])
    first = rows[0]
    model = build_model(load_config(EXAMPLE))
    summary = solve_periodic(model, rpm_to_rad_s(float(first["speed_rpm"])), harmonics=load_config(EXAMPLE).solver.harmonics,
                             samples=load_config(EXAMPLE).solver.time_samples).summary()
    for name in names:
        assert float(first[name]) == pytest.approx(summary[name], rel=1e-6)
        assert float(first[name]) > 0
    assert (out / "bearing_forces.png").stat().st_size > 0 and (out / "modes.json").exists()
    for name in ("pinion_loa", "pinion_oloa", "gear_loa", "gear_oloa"):  # order tracking of each force
        assert (out / f"bearing_orders_{name}.png").stat().st_size > 0
    # the order figure's numbers are orders.csv's bearing columns
    orders = list(csv.DictReader((out / "orders.csv").open()))
    assert float(orders[0]["bearing_force_gear_oloa_order_1_N"]) > 0
