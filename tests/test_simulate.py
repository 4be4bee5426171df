"""Time integration (hbgear.gear.simulate): energy balance, linear closed form, tolerance, steady state,
fixed-length marching, the reaction boundary against harmonic balance."""

import math

import numpy as np
import pytest

from hbgear.build import build_model
from hbgear.config import load_config, parse_config
from hbgear.errors import ConvergenceError
from hbgear.gear.simulate import _steady_period, march, simulate
from hbgear.gear.solve import solve_periodic
from hbgear.gear.monodromy import multipliers_linear

BASE = {
    "gear": dict(teeth_pinion=25, teeth_gear=31, module_mm=3.175, contact_ratio=1.433,
                 inertia_pinion_kgm2=1.0594e-3, inertia_gear_kgm2=2.5047e-3),
    "mesh": dict(k_max_MN_per_m=720.0, k_mean_MN_per_m=568.0, damping_ratio=0.05),
    "load": dict(torque_pinion_Nm=226.0),
    "friction": dict(law="coulomb", mu0=0.1, model="LTV", formulation="A"),
    "boundary": dict(output="spring", damping_ratio=0.1),
}
RPM = 3000.0
OMEGA = RPM * math.pi / 30


def model_for(**sections):
    data = {k: dict(v) for k, v in BASE.items()}
    for name, values in sections.items():
        data[name].update(values)
    return build_model(parse_config(data))


@pytest.fixture(scope="module")
def spring_run():
    return simulate(model_for(), OMEGA)


def test_energy_balance_spring(spring_run):
    s = spring_run.summary
    assert spring_run.period_cycles == 1
    assert s["mean_friction_loss_W"] > 100.0  # ~960 W: friction matters here
    balance = s["mean_friction_loss_W"] + s["mean_mesh_power_W"]
    assert s["mean_power_loss_W"] == pytest.approx(balance, rel=5e-3)
    assert s["mean_power_loss_W"] == pytest.approx(balance, rel=1e-5)  # what we actually get
    # the loss is input minus output, and the input is T_p times the mean pinion speed
    assert s["mean_input_power_W"] == pytest.approx(226.0 * OMEGA, rel=1e-6)


def test_linear_closed_form_lti_torques():
    """mu0 = 0, LTI, constant torques: m_e x'' + c x' + k_mean x = k_mean d + c d', d = N/k(t)."""
    model = model_for(friction=dict(law="none", mu0=0.0, model="LTI"), boundary=dict(output="torques"))
    res = simulate(model, OMEGA, period_cycles=(1,))
    s, q, _, w = res.nodes
    orders = np.arange(1, 9)
    x_ti = np.array([np.sum(w * q[0] * np.exp(-2j * np.pi * n * s)) for n in orders])
    # independent closed form: Fourier coefficients of the rectangular pulse N/k(t)
    load = model.normal_load_N
    ta = model.contact_ratio - 1.0
    kmax, kmin = model.k_max_N_per_m, model.k_min_N_per_m
    d_n = (load / kmax - load / kmin) * (1 - np.exp(-2j * np.pi * orders * ta)) / (2j * np.pi * orders)
    me = model.mass_equivalent_kg
    kmean = kmax * ta + kmin * (1 - ta)
    c = 2 * 0.05 * math.sqrt(kmean * me)
    wn = orders * 25 * OMEGA
    x_cf = (kmean + 1j * wn * c) * d_n / (kmean - me * wn**2 + 1j * wn * c)
    np.testing.assert_allclose(np.abs(x_ti), np.abs(x_cf), rtol=1e-5)
    np.testing.assert_allclose(x_ti, x_cf, atol=1e-5 * np.abs(x_cf).max())
    assert res.summary["dte_mean_um"] == pytest.approx(1e6 * load / kmean, rel=1e-6)
    # constant torques: the mean input power has nothing to balance (MODEL.md section 4)
    assert res.summary["mean_power_loss_W"] == pytest.approx(0.0, abs=1e-6 * res.summary["mean_input_power_W"])


def test_tolerance_independence(spring_run):
    tight = simulate(model_for(), OMEGA, rtol=1e-10, atol=1e-16)
    assert tight.summary["dte_rms_um"] == pytest.approx(spring_run.summary["dte_rms_um"], rel=1e-6)
    assert tight.summary["dte_p2p_um"] == pytest.approx(spring_run.summary["dte_p2p_um"], rel=1e-6)


def test_not_steady_raises():
    with pytest.raises(ConvergenceError, match=r"3000 rpm.*4 mesh cycles.*damping"):
        simulate(model_for(mesh=dict(damping_ratio=0.01)), OMEGA, max_cycles=4)


def test_steady_period_detection_logic():
    tol = 1e-6
    # a converged 1-cycle state
    assert _steady_period([(1e-7, 2e-7), (5e-8, 9e-8)], tol, (1, 2)) == 1
    # a genuine 2-cycle: successive cycles differ by a constant amount, every other one repeats
    assert _steady_period([(0.3, 1e-8), (0.3, 1e-8)], tol, (1, 2)) == 2
    assert _steady_period([(0.3, 1e-8), (0.3, 1e-8)], tol, (1,)) is None
    # a decaying transient with multiplier near -1: c2 small but c1 shrinking -> not a 2-cycle
    assert _steady_period([(1e-2, 1e-7), (5e-3, 5e-8)], tol, (1, 2)) is None
    # one good check is not enough
    assert _steady_period([(1e-2, 1e-2), (1e-8, 1e-8)], tol, (1, 2)) is None



def reaction_output_torque_Nm(model):
    """Output torque of the reaction boundary for LTV-A Coulomb friction, exactly.

    Periodicity of the output equation fixes ``R = <F_2> = N + <T_fp>/R_bp + <T_fg>/R_bg``; in LTV-A the
    friction torques are ``T_fp/R_bp + T_fg/R_bg = mu0 N sum_j sigma_j sgn(xi_p,j - x_P) a(xi_p,j)``
    with the moment arm ``a(xi) = L/R_bg - xi (1/R_bp + 1/R_bg)``, whatever the vibration. With
    ``xi_p,j = x_A + p_b (s + j)`` the mean is a sum of integrals of ``sgn(xi - x_P) a(xi)`` over the
    pieces where the pairs in contact do not change (shares 1/2 for ``s < Gamma - 1``, then 1).
    **Returns:** ``R_bg R`` [N m].
    """
    L, rbp, rbg = model.line_of_action_m, model.base_radius_pinion_m, model.base_radius_gear_m
    pitch, start = model.base_pitch_m, model.contact_start_m
    x_pitch = L * model.teeth_pinion / (model.teeth_pinion + model.teeth_gear)
    alpha, beta = L / rbg, -(1 / rbp + 1 / rbg)

    def mean_signed_arm(slot, lo, hi):
        def primitive(x):
            return alpha * x + 0.5 * beta * x * x
        x0, x1 = start + pitch * (lo + slot), start + pitch * (hi + slot)
        mid = min(max(x_pitch, x0), x1)
        return ((primitive(x1) - primitive(mid)) - (primitive(mid) - primitive(x0))) / pitch

    g1 = model.contact_ratio - 1.0
    mean = 0.5 * (mean_signed_arm(0, 0.0, g1) + mean_signed_arm(1, 0.0, g1)) + mean_signed_arm(0, g1, 1.0)
    return rbg * model.normal_load_N * (1.0 + model.friction.mu0 * mean)


def test_simulate_command_writes_outputs(tmp_path):
    import csv
    import json

    import hbgear.cli.simulate  # noqa: F401  (registers the command)
    from hbgear import cli

    example = str(__import__("pathlib").Path(__file__).resolve().parent.parent / "examples" / "paper_table1.toml")
    common = ["simulate", example, "--speed", "3000", "--set", "mesh.damping_ratio=0.2",
              "--set", "boundary.damping_ratio=0.1"]
    assert cli.main(common + ["--out", str(tmp_path / "ok")]) == 0
    summary = json.loads((tmp_path / "ok" / "summary.json").read_text())
    for key in ("speed_rpm", "dte_rms_um", "dte_p2p_um", "mean_power_loss_W", "mean_friction_loss_W",
                "mean_mesh_power_W", "cycles_integrated", "period_mesh_cycles", "steady_measure"):
        assert key in summary
    assert summary["speed_rpm"] == 3000.0
    with open(tmp_path / "ok" / "timeseries.csv") as fh:
        rows = list(csv.reader(fh))
    assert rows[0][:5] == ["time_s", "mesh_phase", "dte_um", "dte_velocity_m_per_s", "mesh_force_N"]
    assert "pair2_sliding_velocity_m_per_s" in rows[0] and len(rows) > 100
    assert (tmp_path / "ok" / "timeseries.png").stat().st_size > 1000
    # the reaction boundary runs too (it was rejected before) and reports its output torque
    assert cli.main(common + ["--set", "boundary.output='reaction'", "--out", str(tmp_path / "reaction")]) == 0
    reaction = json.loads((tmp_path / "reaction" / "summary.json").read_text())
    model = build_model(load_config(example, ["boundary.output='reaction'"]))
    expected = reaction_output_torque_Nm(model)
    assert reaction["output_torque_Nm"] == pytest.approx(expected, rel=1e-12)  # measured 2e-16
    assert expected == pytest.approx(226.0 * 31 / 25 * (1 - 0.01349), rel=1e-4)  # 1.35 % below T_p R_bg/R_bp
    # too few cycles: exit 1, nothing written
    assert cli.main(common + ["--cycles", "3", "--out", str(tmp_path / "bad")]) == 1
    assert not (tmp_path / "bad").exists() or not any((tmp_path / "bad").iterdir())


# ----------------------------------------------------------------------------- march


def test_march_continued_equals_one_run():
    """N cycles, then N more from the returned state (and output force), equal 2N at once."""
    model = model_for(friction=dict(law="arctan", v0_m_per_s=0.01, model="NLTV"), boundary=dict(output="reaction"))
    whole = march(model, OMEGA, 6)
    first = march(model, OMEGA, 3)
    second = march(model, OMEGA, 3, initial_state=first.final_state, reaction_N=first.final_reaction_N,
                   first_cycle=3)
    np.testing.assert_allclose(np.concatenate([first.q, second.q]), whole.q, rtol=1e-12, atol=1e-18)
    np.testing.assert_allclose(np.concatenate([first.reaction_force_N, second.reaction_force_N]),
                               whole.reaction_force_N, rtol=1e-14)
    np.testing.assert_allclose(second.final_state, whole.final_state, rtol=1e-12, atol=1e-18)
    assert whole.cycles == 6 and not whole.stopped_early
    # the output force moves from its quasi-static start as the dynamic friction settles
    assert whole.reaction_force_N[0] != whole.reaction_force_N[-1]


def test_march_settles_on_the_simulated_steady_state():
    model = model_for(boundary=dict(output="torques"))
    steady = simulate(model, OMEGA, period_cycles=(1,))
    run = march(model, OMEGA, steady.cycles + 10)
    assert run.dte_rms_um[-1] == pytest.approx(steady.summary["dte_rms_um"], rel=1e-6)
    assert run.dte_p2p_um[-1] == pytest.approx(steady.summary["dte_p2p_um"], rel=1e-6)
    assert run.dte_mean_um[-1] == pytest.approx(steady.summary["dte_mean_um"], rel=1e-8)
    # the transient from the static state: the first cycle differs clearly
    assert abs(run.dte_p2p_um[0] / steady.summary["dte_p2p_um"] - 1) > 1e-2
    np.testing.assert_allclose(run.q[-1, 0], steady.q[0, -run.s.size:], rtol=0, atol=1e-6 * np.ptp(steady.q[0]))


def test_march_grows_at_the_monodromy_multiplier():
    """LTV-A in the primary parametric zone (w_m ~ 2 w_n): the deviation from the (unstable)
    periodic solution grows by the exact Floquet multiplier every mesh cycle."""
    model = model_for(mesh=dict(damping_ratio=0.01), boundary=dict(output="torques"))
    omega = 26800.0 * math.pi / 30
    mult = multipliers_linear(model, omega)
    lead = mult[np.argmax(np.abs(mult))]
    assert abs(lead) > 1.2 and abs(lead.imag) < 1e-12
    run = march(model, omega, 50)
    # successive Poincare differences remove the periodic solution: d_n ~ lead^n
    diffs = np.diff(run.start_states, axis=0)
    np.testing.assert_allclose(diffs[-10:] / diffs[-11:-1], lead.real, rtol=1e-6)
    assert run.dte_p2p_um[-1] / run.dte_p2p_um[-11] == pytest.approx(abs(lead) ** 10, rel=1e-4)


def test_march_stops_at_the_dte_limit():
    model = model_for(mesh=dict(damping_ratio=0.01), boundary=dict(output="torques"))
    run = march(model, 26800.0 * math.pi / 30, 200, max_abs_dte_m=1e-3)
    assert run.stopped_early and run.cycles < 200
    assert np.max(np.abs(run.q[-1, 0])) > 1e-3 >= np.max(np.abs(run.q[-2, 0]))


# ----------------------------------------------------------------------------- reaction boundary


@pytest.mark.parametrize("coupling", ["LTV", "NLTV"])
def test_reaction_boundary_matches_harmonic_balance(coupling):
    """Free output inertia with a constant output torque fixed by periodicity: TI against HB."""
    model = model_for(friction=dict(law="arctan", v0_m_per_s=0.01, model=coupling), boundary=dict(output="reaction"))
    ti = simulate(model, OMEGA, period_cycles=(1,))
    hb = solve_periodic(model, OMEGA, harmonics=64, samples=1024)
    hs, ts = hb.summary(), ti.summary
    close = 1e-5 if coupling == "LTV" else 1e-4  # NLTV: HB truncation of the arctan friction
    assert ts["dte_rms_um"] == pytest.approx(hs["dte_rms_um"], rel=close)
    assert ts["dte_p2p_um"] == pytest.approx(hs["dte_p2p_um"], rel=5 * close)
    assert ts["dte_mean_um"] == pytest.approx(hs["dte_mean_um"], rel=close)
    assert ti.reaction_force_N == pytest.approx(hb.reaction_force_N, rel=close / 10)
    # the output force is not the input's rigid balance T_p/R_bp: the mean friction torques enter
    assert abs(ti.reaction_force_N / model.normal_load_N - 1) > 1e-3
    # energy balance of the steady period: loss = friction loss + mesh power
    assert ts["mean_friction_loss_W"] > 900.0
    balance = ts["mean_friction_loss_W"] + ts["mean_mesh_power_W"]
    assert ts["mean_power_loss_W"] == pytest.approx(balance, rel=1e-7)
    assert ts["mean_power_loss_W"] == pytest.approx(hs["mean_power_loss_W"], rel=10 * close)
    # the rigid-body drift is removed: the gear turns at its nominal speed on average
    s, q, qd, w = ti.nodes
    assert abs(np.sum(w * qd[1])) < 1e-9 * model.base_radius_gear_m * OMEGA * 25 / 31



def test_simulate_command_march_fixed_cycles(tmp_path):
    """`--march`: exactly --cycles cycles, per-cycle read-outs equal to march() itself."""
    import csv
    import json

    import hbgear.cli.simulate  # noqa: F401  (registers the command)
    from hbgear import cli
    from hbgear.build import build_model
    from hbgear.config import load_config

    example = __import__("pathlib").Path(__file__).resolve().parent.parent / "examples" / "paper_table1.toml"
    settings = ["boundary.output='torques'"]
    args = ["simulate", str(example), "--speed", "26800", "--cycles", "30", "--march", "--out", str(tmp_path)]
    for item in settings:
        args += ["--set", item]
    assert cli.main(args) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["mode"] == "march" and summary["cycles_integrated"] == 30
    with open(tmp_path / "cycles.csv") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["cycle", "dte_mean_um", "dte_rms_um", "dte_p2p_um"] and len(rows) == 31
    config = load_config(example, settings)
    model = build_model(config)
    rec = march(model, 26800 * math.pi / 30, 30, rtol=config.simulate.rtol, atol=config.simulate.atol_m)
    np.testing.assert_allclose([float(r[3]) for r in rows[1:]], rec.dte_p2p_um, rtol=1e-12)
    assert summary["dte_p2p_um"] == pytest.approx(rec.last_summary["dte_p2p_um"], rel=1e-12)
    # in the primary parametric zone the response grows by the exact multiplier per cycle
    lead = np.max(np.abs(multipliers_linear(model, 26800 * math.pi / 30)))
    assert summary["dte_p2p_growth_per_cycle"] == pytest.approx(lead, rel=1e-3)
    with open(tmp_path / "timeseries.csv") as fh:
        assert next(csv.reader(fh))[:3] == ["time_s", "mesh_phase", "dte_um"]
    assert (tmp_path / "timeseries.png").stat().st_size > 1000
