"""Profile shift in GearPair: textbook examples and the bit-identical unshifted limit."""

import math

import pytest

from hbgear.gear.geometry import GearPair, involute, inverse_involute

PHI = math.radians(20.0)


def test_unshifted_pair_bit_identical_to_the_plain_formulas():
    # the formulas GearPair used before profile shift existed, written out
    pair = GearPair(25, 31, 3.175e-3, PHI, 0.858)
    m, ha = 3.175e-3, 0.858
    rp, rg = m * 25 / 2, m * 31 / 2
    rbp, rbg = rp * math.cos(PHI), rg * math.cos(PHI)
    length = (rp + rg) * math.sin(PHI)
    assert pair.line_of_action_m == length
    assert pair.contact_start_m == length - math.sqrt((rg + ha * m) ** 2 - rbg**2)
    assert pair.contact_end_m == math.sqrt((rp + ha * m) ** 2 - rbp**2)
    assert pair.pitch_point_m == rbp * math.tan(PHI)
    assert pair.working_pressure_angle_rad == PHI
    assert pair.center_distance_m == rp + rg


@pytest.mark.parametrize("angle_deg", [0.5, 14.5, 20.0, 26.0886, 40.0, 60.0])
def test_inverse_involute_solves_to_rounding(angle_deg):
    value = involute(math.radians(angle_deg))
    root = inverse_involute(value)
    # the residual is at rounding level; below ~10 deg tan(a) - a itself loses digits to
    # cancellation, so the angle is compared only where inv is well conditioned
    assert abs(involute(root) - value) <= 4 * math.ulp(value)
    if angle_deg >= 10:
        assert root == pytest.approx(math.radians(angle_deg), rel=1e-15)


def test_khk_profile_shifted_pair_zero_backlash():
    # KHK Gear Technical Reference, "profile shifted spur gears" example: m = 3, 20 deg,
    # z = 12/24, x = 0.60/0.36 -> inv(aw) = 0.034316, aw = 26.0886 deg, y = 0.83329,
    # a = 56.4999 mm, tip diameters 44.840/79.400 mm (tips shortened by (x1 + x2 - y) m),
    # contact ratio 1.20.
    pair = GearPair(12, 24, 3e-3, PHI, profile_shift_pinion=0.6, profile_shift_gear=0.36, tip_shortening=True)
    assert round(involute(pair.working_pressure_angle_rad), 6) == 0.034316
    assert round(math.degrees(pair.working_pressure_angle_rad), 4) == 26.0886
    assert round(pair.center_distance_modification, 5) == 0.83329
    assert round(pair.center_distance_m * 1e3, 4) == 56.4999
    assert round(2e3 * pair.tip_radius_pinion_m, 3) == 44.840
    assert round(2e3 * pair.tip_radius_gear_m, 3) == 79.400
    assert round(pair.contact_ratio, 2) == 1.20


def test_khk_pair_at_imposed_center_distance():
    # The same pair at a = 56.500 mm (worked table at bolsover.com, "Profile Shifted External
    # Spur Gears", after the KHK reference): inv(aw) = 0.034317, aw = 26.0888 deg,
    # y = 0.83333, working pitch diameter 37.667 mm, tip diameters 44.840/79.400 mm,
    # contact ratio 1.202.
    pair = GearPair(12, 24, 3e-3, PHI, profile_shift_pinion=0.6, profile_shift_gear=0.36,
                    working_center_distance_m=56.5e-3, tip_shortening=True)
    assert round(involute(pair.working_pressure_angle_rad), 6) == 0.034317
    assert round(math.degrees(pair.working_pressure_angle_rad), 4) == 26.0888
    assert round(pair.center_distance_modification, 5) == 0.83333
    working_pitch_diameter = 2 * pair.base_radius_pinion_m / math.cos(pair.working_pressure_angle_rad)
    assert round(working_pitch_diameter * 1e3, 3) == 37.667
    assert round(2e3 * pair.tip_radius_pinion_m, 3) == 44.840
    assert round(2e3 * pair.tip_radius_gear_m, 3) == 79.400
    assert round(pair.contact_ratio, 3) == 1.202


def test_fzg_c14_path_of_contact():
    # FZG type C14 test gears (z = 16/24, m = 4.5 mm, x = 0.1817/0.1715, a = 91.5 mm), as
    # reported by the GEARpie program (REPORT/C14.txt): tip radii 41.228/59.182 mm,
    # T1T2 = 34.93 mm, base pitch 13.285 mm, AC = 9.50 mm, AE = 19.10 mm, eps_alpha = 1.44.
    pair = GearPair(16, 24, 4.5e-3, PHI, profile_shift_pinion=0.1817, profile_shift_gear=0.1715,
                    working_center_distance_m=91.5e-3, tip_shortening=True)
    assert round(pair.tip_radius_pinion_m * 1e3, 3) == 41.228
    assert round(pair.tip_radius_gear_m * 1e3, 3) == 59.182
    assert round(pair.line_of_action_m * 1e3, 2) == 34.93
    assert round(pair.base_pitch_m * 1e3, 3) == 13.285
    assert round((pair.pitch_point_m - pair.contact_start_m) * 1e3, 2) == 9.50
    assert round((pair.contact_end_m - pair.contact_start_m) * 1e3, 2) == 19.10
    assert round(pair.contact_ratio, 2) == 1.44


def test_shift_without_tip_shortening_uses_full_addendum():
    pair = GearPair(20, 40, 2e-3, PHI, profile_shift_pinion=0.3, profile_shift_gear=-0.1)
    assert pair.tip_radius_pinion_m == pytest.approx(20e-3 + 1.3 * 2e-3, rel=1e-15)
    assert pair.tip_radius_gear_m == pytest.approx(40e-3 + 0.9 * 2e-3, rel=1e-15)
    # zero-backlash distance: the imposed-distance route with that distance agrees
    same = GearPair(20, 40, 2e-3, PHI, profile_shift_pinion=0.3, profile_shift_gear=-0.1,
                    working_center_distance_m=pair.center_distance_m)
    assert same.working_pressure_angle_rad == pytest.approx(pair.working_pressure_angle_rad, rel=1e-13)
    pair.check()
