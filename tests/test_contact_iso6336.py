"""ISO 6336-1 method B stiffness: a published worked example, the factors, the path shape."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hbgear.gear.contact import Iso6336PairStiffness, iso6336_stiffness, pair_positions
from hbgear.gear.contact.iso6336 import parabola_curvature
from hbgear.gear.geometry import GearPair

jax.config.update("jax_enable_x64", True)

PHI = math.radians(20.0)


def test_iso_tr_6336_30_example_1():
    # ISO/TR 6336-30:2017, calculation example 1 (helical pair, m_n = 8 mm, alpha_n = 20 deg,
    # beta = 15.8 deg, z = 17/103, x = 0.145/0, basic rack with h_fP = 1.4 m_n), reference
    # values as tabulated in the gfsReboucas/Drivetrain repository (ISO_6336.m, example_01):
    # z_n = 18.905/114.543, c'_th = 17.85584, c' = 12.37047 N/(mm um).
    r = iso6336_stiffness((17, 103), (0.145, 0.0), 1.5, helix_angle_rad=math.radians(15.8),
                          rack_dedendum_coefficient=(1.4, 1.4))
    assert round(r.virtual_teeth[0], 3) == 18.905
    assert round(r.virtual_teeth[1], 3) == 114.543
    assert round(r.c_th_N_per_mm_um, 5) == 17.85584
    assert round(r.c_prime_N_per_mm_um, 5) == 12.37047
    assert r.basic_rack_factor == pytest.approx(0.9, rel=1e-15)
    assert r.line_load_factor == 1.0


def test_spur_polynomial_and_factors():
    r = iso6336_stiffness((25, 31), (0.0, 0.0), 1.433)
    assert r.virtual_teeth == (25.0, 31.0)
    assert r.q_prime_mm_um_per_N == pytest.approx(0.04723 + 0.15551 / 25 + 0.25791 / 31, rel=1e-15)
    assert r.basic_rack_factor == 1.0
    assert r.c_prime_N_per_mm_um == pytest.approx(0.8 / r.q_prime_mm_um_per_N, rel=1e-15)
    assert r.c_gamma_alpha_N_per_mm_um == pytest.approx(r.c_prime_N_per_mm_um * (0.75 * 1.433 + 0.25), rel=1e-15)
    # ISO 53 profile A (h_fP = 1.25 m) gives C_B = 0.975
    assert iso6336_stiffness((25, 31), (0, 0), 1.433, rack_dedendum_coefficient=(1.25, 1.25)).basic_rack_factor \
        == pytest.approx(0.975, rel=1e-15)
    # E scaling with E = 2 E1 E2 / (E1 + E2), E_st = 206 GPa
    mixed = iso6336_stiffness((25, 31), (0, 0), 1.433, youngs_modulus_Pa=(206e9, 103e9))
    assert mixed.c_prime_N_per_mm_um == pytest.approx(r.c_prime_N_per_mm_um * 2 / 3, rel=1e-14)


@pytest.mark.parametrize(("line_load", "factor"), [(25.0, 0.25**0.25), (64.0, 0.64**0.25), (100.0, 1.0),
                                                   (400.0, 1.0), (None, 1.0)])
def test_low_line_load_factor(line_load, factor):
    base = iso6336_stiffness((25, 31), (0.1, -0.1), 1.5)
    r = iso6336_stiffness((25, 31), (0.1, -0.1), 1.5, line_load_N_per_mm=line_load)
    assert r.line_load_factor == pytest.approx(factor, rel=1e-15)
    assert r.c_prime_N_per_mm_um == pytest.approx(base.c_prime_N_per_mm_um * factor, rel=1e-15)


def gauss_mesh_mean(pair, shape, order=8):
    """Mesh-period mean of sum_j k_pair(xi_j): Gauss-Legendre on [0, Gamma-1] and [Gamma-1, 1]
    (the summed stiffness is a polynomial on each piece, so the rule is exact)."""
    nodes, weights = np.polynomial.legendre.leggauss(order)
    total = 0.0
    for a, b in ((0.0, pair.contact_ratio - 1.0), (pair.contact_ratio - 1.0, 1.0)):
        s = 0.5 * (b - a) * nodes + 0.5 * (a + b)
        xi, contact = pair_positions(pair, s)
        k = np.where(contact, shape.stiffness(xi - pair.contact_start_m), 0.0)
        total += 0.5 * (b - a) * np.sum(weights * k.sum(axis=0))
    return total


@pytest.mark.parametrize("gamma", [1.2, 1.35, 1.5, 1.7, 1.9])
def test_shape_maximum_and_mesh_mean(gamma):
    pair = GearPair.with_contact_ratio(25, 31, 3.175e-3, PHI, gamma)
    shape, numbers = Iso6336PairStiffness.from_geometry(pair, 0.020)
    b_mm = 20.0
    path = pair.contact_end_m - pair.contact_start_m
    xi = np.linspace(0.0, path, 2001)
    k = shape.stiffness(xi)
    assert k.max() == pytest.approx(numbers.c_prime_N_per_mm_um * b_mm * 1e6, rel=1e-12)
    assert shape.stiffness(0.5 * path) == pytest.approx(numbers.c_prime_N_per_mm_um * b_mm * 1e6, rel=1e-12)
    assert np.all(k > 0)
    mean = gauss_mesh_mean(pair, shape)
    assert mean == pytest.approx(numbers.c_gamma_alpha_N_per_mm_um * b_mm * 1e6, rel=1e-12)
    # end value 1 - a of the peak
    assert shape.stiffness(0.0) == pytest.approx(shape.peak_N_per_m * (1 - parabola_curvature(gamma)), rel=1e-12)


def test_shape_evaluates_with_jax():
    pair = GearPair.with_contact_ratio(25, 31, 3.175e-3, PHI, 1.433)
    shape, _ = Iso6336PairStiffness.from_geometry(pair, 0.020)
    xi = np.linspace(-1e-3, 0.02, 77)
    out = jax.jit(lambda x: shape.stiffness(x, jnp))(xi)
    np.testing.assert_allclose(np.asarray(out), shape.stiffness(xi), rtol=1e-15)
