"""Per-pair tooth contact in the dynamic model (MODEL.md section 9; hbgear.gear.mesh).

Each check is an independent route: the rectangular model (the constant-stiffness limit), the
library's static-TE solve and a scalar root solve per phase (the quasi-static limit and the static
state), time integration (HB with relief and partial contact loss), the variational monodromy
(Hill on a relieved pair)."""

import math
from dataclasses import replace

import numpy as np
import pytest
from scipy.optimize import brentq

from hbgear.build import build_model
from hbgear.config import parse_config
from hbgear.gear.contact import ConstantPairStiffness, static_transmission_error
from hbgear.gear.contact.profile import FlankRelief, ProfileModification
from hbgear.gear.mesh import PairContactMesh, RectangularMesh
import hbgear
from hbgear.gear.solve import solve_periodic

K1_MN = 300.0
BASE = {
    "gear": dict(teeth_pinion=25, teeth_gear=31, module_mm=3.175, contact_ratio=1.433,
                 inertia_pinion_kgm2=1.0594e-3, inertia_gear_kgm2=2.5047e-3),
    "mesh": dict(k_max_MN_per_m=2 * K1_MN, k_min_MN_per_m=K1_MN, damping_ratio=0.05, damping_model="proportional"),
    "load": dict(torque_pinion_Nm=226.0),
    "friction": dict(law="coulomb", mu0=0.1, model="LTV", formulation="A"),
    "boundary": dict(output="spring", damping_ratio=0.1),
}


def rectangular(**sections):
    data = {k: dict(v) for k, v in BASE.items()}
    for name, values in sections.items():
        data[name].update(values)
    return build_model(parse_config(data))


def per_pair(model, stiffness=None, modification=ProfileModification()):
    """`model` with per-pair contact of `stiffness` (default ``k_1 = k_min``) and `modification`."""
    stiffness = stiffness or ConstantPairStiffness(float(model.k_min_N_per_m))
    return model.replace(mesh=PairContactMesh.build(stiffness, modification, model))


def tip_relief(model, amount_um, length_fraction=1.0):
    """Linear tip relief of both gears over `length_fraction` of the double-contact length."""
    length = length_fraction * (float(model.contact_ratio) - 1.0) * float(model.base_pitch_m)
    flank = FlankRelief(tip_relief_m=amount_um * 1e-6, tip_length_m=length)
    return ProfileModification(pinion=flank, gear=flank)


def _relative(a, b):
    a, b = np.asarray(a), np.asarray(b)
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


# ------------------------------------------------------------------ the exact rectangular limit
LIMIT_CASES = [
    dict(),
    dict(friction=dict(formulation="B")),
    dict(friction=dict(model="NLTV", law="arctan", v0_m_per_s=0.05)),
    dict(friction=dict(model="NLTV", law="arctan", v0_m_per_s=0.05, formulation="B")),
    dict(friction=dict(formulation="B"), boundary=dict(output="torques")),
    dict(friction=dict(model="LTI")),
    dict(friction=dict(law="kelley-lemanski", model="NLTV"), boundary=dict(output="reaction")),
    dict(mesh=dict(backlash_um=40.0)),
    dict(mesh=dict(backlash_um=40.0), friction=dict(formulation="B")),
]


@pytest.mark.parametrize("case", LIMIT_CASES, ids=lambda c: "-".join(f"{v}" for d in c.values() for v in d.values()) or "LTV-A")
def test_constant_pair_stiffness_is_the_rectangular_model(case):
    """MODEL.md section 9's limit: ``k_pair = k_1`` without relief is the rectangular model with
    ``k_max = 2 k_1``, ``k_min = k_1`` and proportional damping (the per-pair damper acts only in
    contact, which these loaded solutions never leave): the same HB solution and Floquet
    multipliers to 1e-12."""
    rect = rectangular(**case)
    pair = per_pair(rect)
    assert float(pair.k_mean_N_per_m) == pytest.approx(float(rect.k_mean_N_per_m), rel=1e-14)
    backlash = "backlash_um" in case.get("mesh", {})
    rpm = 6000.0 if backlash else 4000.0  # with backlash: a speed where the teeth stay in contact
    a = hbgear.solve(rect, speed_rpm=rpm, harmonics=24)
    b = hbgear.solve(pair, speed_rpm=rpm, harmonics=24)
    assert _relative(b.coefficients, a.coefficients) < 1e-12
    ma, mb = (np.sort_complex(np.asarray(s.multipliers)) for s in (a, b))
    assert ma.shape == mb.shape and np.max(np.abs(ma - mb)) < 1e-12
    if backlash:  # the regime of the limit: the drive flank never opens (x > b)
        f = np.linspace(0.0, 1.0, 2048, endpoint=False)
        x = np.asarray(b.state_at(f)[0][0]) - pair.static_transmission_error(f, pair.speeds(b.omega_pinion)[2])[0]
        assert np.min(x) > 0.5 * float(pair.backlash_m) + 1e-6
    else:
        assert pair.is_linear == rect.is_linear


# ------------------------------------------------------------------ the relieved ISO pair
def iso_relief_model(torque_Nm=226.0, relief=True, **changes):
    """examples/iso_tip_relief.toml at `torque_Nm` (its relief designed for 226 N m), model fields `changes`."""
    import tomllib
    from pathlib import Path

    data = tomllib.loads((Path(__file__).parents[1] / "examples" / "iso_tip_relief.toml").read_text())
    data["load"]["torque_pinion_Nm"] = torque_Nm
    if not relief:
        data.pop("profile")
    cfg = parse_config(data)
    from hbgear.build import build_tooth_contact

    return build_model(cfg).replace(**changes), build_tooth_contact(cfg)


def test_static_state_is_the_scalar_root_per_phase():
    """The model's static DTE ``delta_s(s)`` against an independent root solve per phase:
    ``sum_j k_j max(D - e_j, 0) = N`` by Brent's method on the model's pair stiffness and relief."""
    model, contact = iso_relief_model(150.0)
    s = np.linspace(0.0, 1.0, 41, endpoint=False)
    mine = np.asarray(model.static_dte(s, 100.0))
    n = float(model.normal_load_N)
    for phase, delta in zip(s, mine):
        xi = contact.geometry.contact_start_m + contact.geometry.base_pitch_m * (phase + np.arange(2))
        inside = phase + np.arange(2) < float(model.contact_ratio)
        k = np.where(inside, contact.pair_stiffness.stiffness(xi - contact.geometry.contact_start_m), 0.0)
        e = contact.modification.deviation(contact.geometry, xi)
        root = brentq(lambda d: np.sum(k * np.maximum(d - e, 0.0)) - n, 0.0, 1e-3, xtol=1e-18, rtol=1e-15)
        assert delta == pytest.approx(root, rel=1e-12)


def test_quasi_static_limit_is_the_loaded_static_te_and_converges_in_h():
    """At 20 rpm the HB DTE tends to the library's loaded static TE (:func:`static_transmission_error`),
    its Fourier orders 0..8 compared by a Gauss rule between the breakpoints (the static TE is
    smooth there). Frictionless (friction moments change the static balance) with constant torques
    (the spring boundary's soft mode lies below this mesh frequency).

    Expected size of the difference: the dynamic correction of order ``n`` is
    ``~ 2 zeta n r + (n r)^2`` with ``r = w_m/w_n ~ 2e-3`` (<= 4e-4 of that order's amplitude,
    far below the p2p), and the truncation: this pair's static TE jumps at pair entry and exit (the
    relief, 24 um, is a little less than the single-pair deflection at 226 N m, so the entering
    tooth loads at once) and ``k(s)`` jumps there too. HB makes the low orders of
    ``k(s) (x - D(s))`` vanish with ``x`` of degree ``H``; ``D``'s unresolved orders ``m > H``
    (``D_m ~ 1/m``) feed the low orders through ``k``'s (``k_m ~ 1/m``): the error is
    ``sum_{m > H} 1/m^2 ~ 1/H``, order 1 in ``H``. Observed over H = 32, 64, 128: order ~1,
    and below 2e-4 of the p2p at H = 128."""
    from hbgear.engine.quadrature import mesh_period_rule
    from hbgear.gear.friction import NoFriction

    model, contact = iso_relief_model(226.0, friction=NoFriction(), boundary="torques")
    f, w = mesh_period_rule(model.phase_breakpoints(), 64)

    def static(phases=None):
        return static_transmission_error(contact.geometry, contact.pair_stiffness, float(model.normal_load_N),
                                         modification=contact.modification, phases=phases).delta_m

    basis = np.exp(-2j * np.pi * np.arange(9)[:, None] * f[None])
    target, p2p = basis @ (w * static(f)), np.ptp(static())
    errors = []
    for harmonics in (32, 64, 128):
        sol = hbgear.solve(model, speed_rpm=20.0, harmonics=harmonics, stability=False)
        errors.append(np.max(np.abs(basis @ (w * np.asarray(sol.state_at(f)[0][0])) - target)) / p2p)
    order = -np.diff(np.log(errors)) / np.log(2.0)
    assert np.all((order > 0.8) & (order < 1.3)), (errors, order)
    assert errors[-1] < 2e-4


def test_hb_matches_time_integration_with_partial_contact_loss():
    """Relief for 226 N m run at 100 N m: the relieved tips open (pairs carry nothing over part of
    the double-contact zone, and near the resonance the contact of each pair opens and closes with
    the vibration: the dampers' jumps are events). HB (H = 64) against time integration: 0.1 %."""
    model, _ = iso_relief_model(100.0)
    omega = 6000.0 * math.pi / 30
    from hbgear.gear.simulate import simulate

    hb = solve_periodic(model, omega, harmonics=64)
    ti = simulate(model, omega, period_cycles=(1,))
    hs, ts = hb.summary(), ti.summary
    f = np.linspace(0.0, 1.0, 1024, endpoint=False)
    q = np.asarray(hb.state_at(f)[0])
    open_fraction = np.mean(np.asarray(model.pair_contact(f, q, 0.0 * q, omega).drive).sum(axis=0)
                            < np.asarray(model.pair_positions(f)[2]).sum(axis=0))
    assert open_fraction > 0.05  # partial contact loss: some pair of the path open
    for key in ("dte_mean_um", "dte_rms_um", "dte_p2p_um"):
        assert ts[key] == pytest.approx(hs[key], rel=1e-3), key


def test_hill_variational_and_exact_monodromy_on_a_relieved_pair():
    """Relief for 226 N m run at 300 N m: every pair of the path stays loaded, so the relieved
    model is in its linear regime and its variational equations are those of the closed mesh
    (exact monodromy of the linear equivalent). Hill's method, the variational equations along
    the HB solution and the exact monodromy agree."""
    from hbgear.gear.monodromy import floquet_multipliers
    from hbgear.gear.system import GearSystem, linear_equivalent

    model, _ = iso_relief_model(300.0)
    omega = 3000.0 * math.pi / 30
    sol = solve_periodic(model, omega, harmonics=48)
    assert not model.is_linear and linear_equivalent(model, sol) is not None
    var = np.sort_complex(floquet_multipliers(model, omega, solution=sol, method="variational"))
    exact = np.sort_complex(floquet_multipliers(linear_equivalent(model, sol), omega, method="monodromy"))
    assert np.max(np.abs(var - exact)) < 1e-7
    # Hill truncates a coefficient k(t) that jumps at pair entry and exit: it converges in H
    hill = [np.sort_complex(floquet_multipliers(model, omega, solution=solve_periodic(model, omega, harmonics=h),
                                                method="hill")) for h in (48, 96)]
    errors = [np.max(np.abs(m - exact)) for m in hill]
    assert errors[0] < 3e-5 and errors[1] < 0.7 * errors[0], errors


#: Around the resonance of examples/iso_tip_relief.toml (H = 12): folds at 9487, 9185, 9556 and 9136 rpm.
FOLD_RANGE_RPM = (9000.0, 9800.0)


def test_continuation_through_the_contact_loss_folds_of_a_relieved_pair():
    """The relieved iso pair near its resonance: partial contact loss softens the curve, which
    folds at 9487 rpm, runs back on an unstable branch to 9185 rpm, up a stable one to 9556 rpm
    and back on an unstable one to 9136 rpm onto the lower stable branch. The continuation passes
    the four folds to the end of the range, every point within the tolerance, stability
    alternating. (Before the arclength sized the soft output spring's mean wind-up, which follows
    the pairs' mean friction torque 5e5 times more than the mesh, the steps near the fold were
    ~0.1 rpm at H = 32 and the run stopped on the first unstable branch at 9394 rpm.)"""
    model, _ = iso_relief_model(226.0)
    curve = hbgear.frequency_response(model, speed_rpm=FOLD_RANGE_RPM, harmonics=12, samples=256,
                                      max_points=400, period_doubling=False)
    assert curve.success
    folds = [int(f["index"]) for f in curve.fold_records]
    assert np.allclose(curve.folds, [9487.2, 9185.3, 9555.6, 9135.6], atol=1.0), curve.folds
    assert curve.speed_rpm[-1] == FOLD_RANGE_RPM[1]
    assert np.max(np.asarray(curve.residual)) <= 1e-9
    stable = np.asarray(curve.stable, dtype=bool)
    edges = [0, *folds, len(stable)]
    for k in range(5):  # stable, unstable, stable, unstable, stable between the folds
        inner = stable[edges[k] + 2:edges[k + 1] - 1]
        assert len(inner) and (inner.all() if k % 2 == 0 else not inner.any()), k
