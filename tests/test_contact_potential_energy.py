"""Potential-energy tooth compliances: profile geometry and the integrals by a second route."""

import math

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.optimize import brentq

from hbgear.gear.contact.potential_energy import _profile, potential_energy_pair_stiffness, tooth_compliances
from hbgear.gear.geometry import GearPair, involute

PHI = math.radians(20.0)
M, Z, B, E, NU = 3.175e-3, 25, 0.020, 206e9, 0.3


@pytest.mark.parametrize("shift", [0.0, 0.3, -0.2])
def test_profile_thickness_at_the_pitch_circle(shift):
    # tooth thickness on the reference circle s = m (pi/2 + 2 x tan(phi))
    base = M * Z / 2 * math.cos(PHI)
    half_angle = math.pi / (2 * Z) + 2 * shift * math.tan(PHI) / Z + involute(PHI)
    x, h, _ = _profile(PHI, base, half_angle)
    r = M * Z / 2
    assert math.hypot(x, h) == pytest.approx(r, rel=1e-14)
    assert math.atan2(h, x) * r * 2 == pytest.approx(M * (math.pi / 2 + 2 * shift * math.tan(PHI)), rel=1e-13)


@pytest.mark.parametrize("contact_angle_deg", [12.0, 20.0, 27.0])
def test_integrals_against_quadrature_in_the_centreline_coordinate(contact_angle_deg):
    # second route: adaptive quadrature in X itself, inverting X(alpha) by Brent's method
    # (checks the alpha substitution, its Jacobian dX/dalpha and the Gauss rule)
    base = M * Z / 2 * math.cos(PHI)
    half_angle = math.pi / (2 * Z) + involute(PHI)
    alpha_c = math.radians(contact_angle_deg)
    x_c, h_c, _ = _profile(alpha_c, base, half_angle)
    alpha_1 = alpha_c - (half_angle - involute(alpha_c))
    x_base = _profile(0.0, base, half_angle)[0]

    def h_of(x):
        return _profile(brentq(lambda a: _profile(a, base, half_angle)[0] - x, 0.0, alpha_c, xtol=1e-16), base,
                        half_angle)[1]

    def arm(x):
        return (x_c - x) * math.cos(alpha_1) - h_c * math.sin(alpha_1)

    g = E / (2 * (1 + NU))
    bending = quad(lambda x: arm(x) ** 2 / (E * (2 * h_of(x)) ** 3 * B / 12), x_base, x_c, epsabs=0, epsrel=1e-12)[0]
    shear = quad(lambda x: 1.2 * math.cos(alpha_1) ** 2 / (g * 2 * h_of(x) * B), x_base, x_c, epsabs=0,
                 epsrel=1e-12)[0]
    axial = quad(lambda x: math.sin(alpha_1) ** 2 / (E * 2 * h_of(x) * B), x_base, x_c, epsabs=0, epsrel=1e-12)[0]
    parts = tooth_compliances(Z, M, PHI, 0.0, alpha_c, B, E, NU, 12.5e-3)
    assert parts["bending"] == pytest.approx(bending, rel=1e-11)
    assert parts["shear"] == pytest.approx(shear, rel=1e-11)
    assert parts["axial"] == pytest.approx(axial, rel=1e-11)
    assert parts["fillet"] > 0


def test_pair_is_the_series_sum():
    pair = GearPair.with_contact_ratio(25, 31, M, PHI, 1.433)
    table = potential_energy_pair_stiffness(pair, B, E, NU, (12.5e-3, 15e-3), samples=5)
    xi = np.array(table.positions_m)
    xi_p = pair.contact_start_m + xi
    total = 4 * (1 - NU**2) / (math.pi * E * B)
    total = total + sum(tooth_compliances(25, M, PHI, 0.0, np.arctan(xi_p / pair.base_radius_pinion_m), B, E, NU,
                                          12.5e-3).values())
    total = total + sum(tooth_compliances(31, M, PHI, 0.0, np.arctan((pair.line_of_action_m - xi_p)
                                                                     / pair.base_radius_gear_m), B, E, NU,
                                          15e-3).values())
    np.testing.assert_allclose(table.stiffness_N_per_m, 1 / total, rtol=1e-14)
