"""Geometry of the reference pair (MODEL.md section 1): contact ratio, instants, masses, limits."""

import math

import pytest

from hbgear.build import build_model
from hbgear.config import parse_config
from hbgear.errors import ConfigError
from hbgear.gear.geometry import GearPair

PHI = math.radians(20.0)
REF = dict(teeth_pinion=25, teeth_gear=31, module_m=3.175e-3, pressure_angle_rad=PHI)


def test_standard_addendum_contact_ratio():
    pair = GearPair(**REF, addendum_coefficient=1.0).check()
    assert pair.contact_ratio == pytest.approx(1.636, abs=5e-4)
    # pitch point from the base radius and from the line of action agree
    length = pair.line_of_action_m
    assert pair.pitch_point_m == pytest.approx(length * 25 / 56, rel=1e-12)


def test_contact_ratio_solved_gives_paper_instants():
    pair = GearPair.with_contact_ratio(**REF, contact_ratio=1.433)
    assert pair.contact_ratio == pytest.approx(1.433, abs=1e-10)
    assert pair.addendum_coefficient == pytest.approx(0.858, abs=2e-3)
    assert pair.double_contact_fraction == pytest.approx(0.433, abs=1e-10)  # t_a / Tm
    assert pair.pitch_crossing_fraction == pytest.approx(0.726, abs=1e-3)  # t_b / Tm
    # the pitch point lies in single contact, between exit of the old pair and the period end
    assert pair.double_contact_fraction < pair.pitch_crossing_fraction < 1.0
    assert pair.phase_breakpoints() == pytest.approx((0.0, 0.433, pair.pitch_crossing_fraction))


def test_equivalent_mass_and_natural_frequency():
    cfg = parse_config(
        {
            "gear": dict(teeth_pinion=25, teeth_gear=31, module_mm=3.175, contact_ratio=1.433,
                         inertia_pinion_kgm2=1.0594e-3, inertia_gear_kgm2=2.5047e-3),
            "mesh": dict(k_max_MN_per_m=720.0, k_mean_MN_per_m=568.0),
            "load": dict(torque_pinion_Nm=226.0),
        }
    )
    model = build_model(cfg)
    assert model.mass_equivalent_kg == pytest.approx(0.4615, abs=1e-4)
    assert model.k_min_N_per_m == pytest.approx(451.9e6, rel=1e-3)
    wn = math.sqrt(model.k_mean_N_per_m / model.mass_equivalent_kg)
    assert wn == pytest.approx(35080, rel=2e-3)
    # primary resonance w_m = w_n near 13,400 rpm
    assert wn / 25 * 30 / math.pi == pytest.approx(13400, rel=1e-2)


@pytest.mark.parametrize("gamma", [0.95, 1.0, 2.0, 2.3])
def test_contact_ratio_outside_range_rejected(gamma):
    with pytest.raises(ConfigError):
        GearPair.with_contact_ratio(**REF, contact_ratio=gamma)


def test_addendum_giving_contact_ratio_above_two_rejected():
    with pytest.raises(ConfigError):
        GearPair(**REF, addendum_coefficient=1.9).check()
    with pytest.raises(ConfigError):
        GearPair(**REF, addendum_coefficient=0.2).check()  # Gamma < 1
