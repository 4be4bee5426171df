"""The spring boundary's soft output mode in the stability verdict (hbgear.gear.soft_mode).

With ``boundary.damping_ratio = 0`` the soft mode is undamped: its exact multipliers are
``exp(+-i w_b T)``, ``w_b = sqrt(k_u/(m_p + m_g))``, with a modulus of ``1 +- 1e-10``. It is set
apart as neutral (like the reaction boundary's trivial pair), so the verdict does not rest on the
sign of that 1e-10.
"""

from pathlib import Path

import numpy as np
import pytest

from hbgear.build import build_model
from hbgear.config import load_config
from hbgear.engine import floquet
from hbgear.engine.hb import HarmonicBalance
from hbgear.gear.monodromy import multipliers_linear
from hbgear.gear.soft_mode import NEUTRAL_TOL, soft_mode_estimate, split_soft_mode, stable_verdict, stable_verdicts
from hbgear.gear.solve import rpm_to_rad_s, solve_periodic
from hbgear.gear.system import GearSystem

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "paper_table1.toml"
SWEEP_RPM = np.linspace(2000.0, 32000.0, 1201)  # through the resonance and the primary tongue


def gear(*overrides):
    return build_model(load_config(EXAMPLE, list(overrides)))


@pytest.fixture(scope="module")
def spring_sweep():
    """LTV-A, spring boundary without damping of its own: exact multipliers along the sweep."""
    model = gear("friction.model='LTV'", "boundary.damping_ratio=0.0")
    omegas = rpm_to_rad_s(SWEEP_RPM)
    return model, omegas, multipliers_linear(model, omegas)


def test_soft_mode_estimate_is_the_uncoupled_mode():
    model = gear("friction.model='LTV'")
    w = rpm_to_rad_s(3000.0)
    w_b = np.sqrt(model.spring_stiffness_N_per_m / (model.mass_pinion_kg + model.mass_gear_kg))
    angle = w_b * 2 * np.pi / (25 * w)  # one mesh period
    np.testing.assert_allclose(soft_mode_estimate(model, w), np.exp([1j * angle, -1j * angle]), rtol=1e-15)
    np.testing.assert_allclose(soft_mode_estimate(model, w, nu=2), np.exp([2j * angle, -2j * angle]), rtol=1e-15)
    assert soft_mode_estimate(gear("boundary.output='torques'"), w).size == 0
    assert soft_mode_estimate(gear("boundary.output='reaction'"), w).size == 0


def test_undamped_soft_mode_is_neutral_along_a_sweep(spring_sweep):
    """The pair is found at every speed, within 1e-8 of exp(+-i w_b T) (the mesh couples ~5e-9 in),
    its modulus within 1e-9 of 1 and above 1 near the resonance (+1.0e-10 at 13375 rpm): a verdict
    on all multipliers would rest on the tolerance. Set apart, the verdict is the reaction
    boundary's (trivial pair dropped) at every speed, even with no tolerance at all."""
    model, omegas, mult = spring_sweep
    estimate = soft_mode_estimate(model, omegas)
    soft = np.array([split_soft_mode(model, w, m)[1] for w, m in zip(omegas, mult)])
    assert soft.shape == (len(omegas), 2)
    assert np.max(np.abs(np.sort_complex(soft) - np.sort_complex(estimate))) < 1e-8
    excess = np.abs(soft) - 1.0
    assert np.max(np.abs(excess)) < 1e-9 and np.max(excess) > 5e-11
    reaction = multipliers_linear(gear("friction.model='LTV'", "boundary.output='reaction'"), omegas)
    by_reaction = np.array([floquet.is_stable(m, tol=0.0) for m in reaction])
    assert 0 < np.sum(~by_reaction) < len(omegas)  # the sweep crosses unstable zones
    np.testing.assert_array_equal(stable_verdicts(model, omegas, mult, tol=0.0), by_reaction)
    np.testing.assert_array_equal(stable_verdicts(model, omegas, mult), by_reaction)
    # all multipliers with no tolerance: spurious instabilities where the soft mode exceeds 1
    on_all = np.array([floquet.is_stable(m, tol=0.0) for m in mult])
    assert np.sum(~on_all) > np.sum(~by_reaction) + 100
    assert [stable_verdict(model, w, m) for w, m in zip(omegas[::40], mult[::40])] == list(by_reaction[::40])


def test_damped_soft_mode_is_an_ordinary_multiplier():
    """With boundary.damping_ratio = 0.1 the soft pair is exp(-zeta_b w_b T) inside the circle,
    farther than NEUTRAL_TOL from exp(+-i w_b T): nothing is set apart, it counts."""
    model = gear("friction.model='LTV'", "boundary.damping_ratio=0.1")
    w = rpm_to_rad_s(3000.0)
    mult = multipliers_linear(model, w)
    others, soft = split_soft_mode(model, w, mult)
    assert soft.size == 0 and others.size == 4
    slow = mult[np.argmin(np.abs(mult - soft_mode_estimate(model, w)[0]))]
    assert 1 - abs(slow) > 100 * NEUTRAL_TOL


@pytest.mark.parametrize("rpm", [3000.0, 13400.0])
def test_hill_finds_the_same_neutral_pair(spring_sweep, rpm):
    """Hill's method (LTV-A, H = 16) gives the soft pair to ~1e-13 of the exact one: the same pair
    is set apart and the verdict is the exact one."""
    model = spring_sweep[0]
    w = rpm_to_rad_s(rpm)
    hb = HarmonicBalance(model.ndof, 16, 1, 64)
    hill = floquet.hill_multipliers(hb, np.zeros(hb.size), w, GearSystem(model))
    exact = multipliers_linear(model, w)
    soft_hill, soft_exact = split_soft_mode(model, w, hill)[1], split_soft_mode(model, w, exact)[1]
    assert soft_hill.size == 2
    assert np.max(np.abs(np.sort_complex(soft_hill) - np.sort_complex(soft_exact))) < 1e-11
    assert stable_verdict(model, w, hill) and stable_verdict(model, w, exact)


def test_nltv_friction_damped_soft_mode_within_the_band_is_neutral():
    """NLTV friction damps the soft mode (arctan law, v0 = 0.01 m/s: variational modulus 1 - 5.67e-6
    at 3000 rpm): within the band, set apart; Hill's modulus for it (H = 16, N = 256) is within
    2e-9 of the variational one here."""
    from hbgear.gear.monodromy import monodromy_variational

    model = gear("friction.model='NLTV'", "friction.law='arctan'")
    w = rpm_to_rad_s(3000.0)
    sol = solve_periodic(model, w, harmonics=16, samples=256)
    hill = floquet.hill_multipliers(HarmonicBalance(model.ndof, 16, 1, 256), sol.z, w, GearSystem(model))
    exact = np.linalg.eigvals(monodromy_variational(model, sol, w))
    for mult in (hill, exact):
        soft = split_soft_mode(model, w, mult)[1]
        assert soft.size == 2 and 1e-7 < 1 - np.abs(soft).max() < NEUTRAL_TOL
    assert abs(np.abs(split_soft_mode(model, w, hill)[1][0]) - np.abs(split_soft_mode(model, w, exact)[1][0])) < 1e-8


def test_engine_verdicts_leave_out_the_neutral_pair(spring_sweep):
    """The engine's verdict (GearSystem.neutral_multipliers through floquet.stable_verdict) is the
    gear rule's at every speed, and the curve's stable column and the exact zone scan use it."""
    from hbgear.engine.stability import unstable_zones

    model, omegas, mult = spring_sweep
    system = GearSystem(model)
    engine = np.array([floquet.stable_verdict(system, w, m) for w, m in zip(omegas, mult)])
    np.testing.assert_array_equal(engine, stable_verdicts(model, omegas, mult))
    np.testing.assert_array_equal(floquet.stable_verdicts(system, omegas, mult), engine)  # rows at once
    assert engine.any() and not engine.all()
    reaction = gear("friction.model='LTV'", "boundary.output='reaction'")
    from_spring = unstable_zones(system, omegas[::10])
    from_reaction = unstable_zones(GearSystem(reaction), omegas[::10])
    assert [z["parameter_from"] for z in from_spring] == [z["parameter_from"] for z in from_reaction]
    import hbgear

    curve = hbgear.frequency_response(model, speed_rpm=(13000.0, 13800.0), harmonics=8, samples=64,
                                      period_doubling=False, progress=False)
    want = stable_verdicts(model, rpm_to_rad_s(curve.speed_rpm), np.stack(curve.response.multipliers))
    np.testing.assert_array_equal(curve.stable == 1, want)
