"""Period doubling, backlash folds and time-integration sweeps (hbgear.gear.bifurcation).

The reference pair of ``examples/backlash.toml`` reduced to the DTE alone (boundary "torques",
no friction): the cheapest model that has both the parametric tongue around ``w_m = 2 w_n``
(~25,300-28,200 rpm at zeta 0.05) and the softening contact-loss resonance (~11,500-11,900 rpm
at zeta 0.09). Every comparison is against time integration (an independent route).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hbgear.gear.bifurcation import (
    backlash_frc,
    continue_period_doubled,
    embed_subharmonic,
    half_order_indices,
    half_order_share,
    jump_speeds,
    locate_period_doubling,
)
from hbgear.build import build_model
from hbgear.config import load_config
from hbgear.engine.hb import HarmonicBalance
from hbgear.gear.simulate import simulate
from hbgear.gear.solve import PeriodicSolution, rpm_to_rad_s, solve_periodic
from hbgear.gear.monodromy import multipliers_linear
from hbgear.gear.system import GearSystem

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "backlash.toml"
H1, N1 = 8, 256  # shared by every nu = 1 solve below: one compilation


def _model(zeta):
    cfg = load_config(EXAMPLE, ['boundary.output="torques"', f"mesh.damping_ratio={zeta}"])
    return build_model(cfg)


def test_embedding_is_exact_and_solves_the_nu2_equations():
    model = _model(0.05)
    omega = rpm_to_rad_s(20000.0)
    sol = solve_periodic(model, omega, harmonics=H1, samples=N1)
    z2 = embed_subharmonic(sol.z, model.ndof, H1)
    hb2 = HarmonicBalance(model.ndof, 2 * H1, 2, 2 * N1)
    sol2 = PeriodicSolution.from_z(model, omega, z2, hb2)
    # same waveform: mesh fraction f is base fraction f/2, over both mesh periods of the base one
    f = np.linspace(0.0, 1.0, 97)
    q1, qd1 = sol.state_at(f)
    for shift in (0.0, 0.5):
        q2, qd2 = sol2.state_at(f / 2 + shift)
        np.testing.assert_allclose(q2, q1, rtol=0, atol=1e-12 * np.max(np.abs(q1)))
        np.testing.assert_allclose(qd2, qd1, rtol=0, atol=1e-12 * np.max(np.abs(qd1)))
    # no half orders, and it is a solution of the nu = 2 equations (AFT on twice the samples)
    assert np.all(z2[half_order_indices(model.ndof, 2 * H1)] == 0.0)
    assert half_order_share(z2, model.ndof, 2 * H1) == 0.0
    r = np.asarray(hb2.residual(z2, omega, GearSystem(model)))
    assert np.max(np.abs(r)) < 1e-8
    # truncation keeps the low orders only
    z_cut = embed_subharmonic(sol.z, model.ndof, H1, harmonics_to=5)
    np.testing.assert_array_equal(z_cut[[3, 4]], sol.z[[1, 2]])
    np.testing.assert_array_equal(z_cut[[7, 8]], sol.z[[3, 4]])
    assert z_cut.size == 11


def test_period_doubled_branch_matches_bounded_time_integration():
    """LTV parametric tongue (w_m ~ 2 w_n) bounded by backlash: nu = 2 HB against TI."""
    model = _model(0.05)
    point = locate_period_doubling(model, rpm_to_rad_s(27900.0), rpm_to_rad_s(28500.0), harmonics=H1, samples=N1)
    assert point.multiplier == pytest.approx(-1.0, abs=1e-5)
    # the nu = 1 solution there keeps contact, so the crossing is the linear tongue's upper edge
    linear = model.replace(contact="linear")
    edge = np.min(np.real(multipliers_linear(linear, point.omega)))
    assert edge == pytest.approx(-1.0, abs=1e-4)
    assert 27900.0 < point.speed_rpm < 28500.0

    target = rpm_to_rad_s(26000.0)
    branch = continue_period_doubled(model, point, target, harmonics=2 * H1, samples=512)
    assert branch.reached, branch.message
    hb_sol = branch.solution(-1)
    assert hb_sol.nu == 2 and hb_sol.speed_rpm == pytest.approx(26000.0)
    assert half_order_share(hb_sol.z, model.ndof, hb_sol.harmonics) > 0.3
    hb = hb_sol.summary()

    ti = simulate(model, target, max_cycles=1500, rtol=1e-8, steady_tolerance=1e-6)
    assert ti.period_cycles == 2
    for key in ("dte_p2p_um", "dte_rms_um"):
        assert hb[key] == pytest.approx(ti.summary[key], rel=0.01), key
    # bounded: the teeth separate (p2p beyond the static deflection), yet the response is finite
    assert hb["dte_p2p_um"] > 20.0


def test_backlash_folds_against_time_integration_sweeps():
    """Softening contact-loss resonance: HB fold speeds against TI jump speeds, to 1%."""
    model = _model(0.09)
    curve = backlash_frc(model, 11000.0, 12500.0, harmonics=H1, samples=N1)
    assert curve.status.name == "SUCCESS", curve.message
    assert len(curve.fold_speeds_rpm) == 2
    fold_high, fold_low = np.max(curve.fold_speeds_rpm), np.min(curve.fold_speeds_rpm)
    assert fold_high - fold_low > 200.0  # a real hysteresis loop, wider than the TI resolution

    jumps = jump_speeds(model, 11300.0, 12100.0, 200.0, resolution_rpm=100.0, rtol=1e-7, steady_tolerance=1e-5)
    # softening: sweeping up, the small branch ends at the upper fold (jump up);
    # sweeping down, the contact-loss branch ends at the lower fold (jump down)
    assert jumps.up_rpm == pytest.approx(fold_high, rel=0.01)
    assert jumps.down_rpm == pytest.approx(fold_low, rel=0.01)
    assert jumps.up_bracket_rpm[0] <= fold_high <= jumps.up_bracket_rpm[1]
    assert min(jumps.down_bracket_rpm) <= fold_low <= max(jumps.down_bracket_rpm)
    up_jump = jumps.up.dte_p2p_um[np.searchsorted(jumps.up.speed_rpm, 11900.0)]
    assert up_jump > 1.4 * jumps.up.dte_p2p_um[0]
