"""Per-pair tooth contact in the dynamic model (MODEL.md section 9; hbgear.gear.mesh): the
rectangular model is the constant-stiffness limit.

The other routes are in files of their own (each file goes whole to one test process): the
library's static-TE solve and a scalar root solve per phase (test_pair_contact_static.py), the
variational and exact monodromy and continuation through the contact-loss folds
(test_pair_contact_stability.py), time integration and the energy identity with partial contact
loss (test_pair_contact_checks.py)."""

import numpy as np
import pytest

from hbgear.build import build_model
from hbgear.config import parse_config
from hbgear.gear.contact import ConstantPairStiffness
from hbgear.gear.contact.profile import FlankRelief, ProfileModification
from hbgear.gear.mesh import PairContactMesh
import hbgear

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
