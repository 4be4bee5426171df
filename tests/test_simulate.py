"""Time integration (hbgear.simulate): energy balance, linear closed form, tolerance, steady state."""

import math

import numpy as np
import pytest

from hbgear.build import build_model
from hbgear.config import parse_config
from hbgear.errors import ConvergenceError
from hbgear.simulate import _steady_period, simulate

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



def test_simulate_command_writes_outputs(tmp_path):
    import csv
    import json

    import hbgear.commands.simulate  # noqa: F401  (registers the command)
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
    # too few cycles: exit 1, nothing written
    assert cli.main(common + ["--cycles", "3", "--out", str(tmp_path / "bad")]) == 1
    assert not (tmp_path / "bad").exists() or not any((tmp_path / "bad").iterdir())
