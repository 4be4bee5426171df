"""Loaded static TE: exact piecewise-linear solve against a scalar root solve, limits, Harris map."""

import math
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import brentq

from hbgear.gear.contact import (
    ConstantPairStiffness,
    FlankRelief,
    Iso6336PairStiffness,
    ProfileModification,
    RectangularMeshStiffness,
    TablePairStiffness,
    harris_map,
    loaded_te_table,
    pair_positions,
    pair_stiffness_max,
    solve_static_contact,
    static_transmission_error,
    unloaded_ste,
)
from hbgear.gear.geometry import GearPair

jax.config.update("jax_enable_x64", True)

PAIR = GearPair.with_contact_ratio(25, 31, 3.175e-3, math.radians(20.0), 1.433)
LOAD = 226.0 / PAIR.base_radius_pinion_m  # N = T_p / R_bp
ISO, _ = Iso6336PairStiffness.from_geometry(PAIR, 0.020)
RELIEF_LENGTH = (PAIR.contact_ratio - 1.0) * PAIR.base_pitch_m  # "long" relief


def scalar_solve(k, g, load):
    """delta of sum k max(delta - g, 0) = N by Brent's method on the increasing function."""
    def f(delta):
        return float(np.sum(k * np.maximum(delta - g, 0.0))) - load
    lo = float(np.min(g))
    hi = float(np.max(g)) + 2 * load / float(np.min(k))
    return brentq(f, lo, hi, xtol=1e-22, rtol=4 * np.finfo(float).eps, maxiter=500)


def test_against_scalar_root_solve_per_phase():
    mod = ProfileModification(FlankRelief(6e-6, 0.8 * RELIEF_LENGTH, shape="parabolic"),
                              FlankRelief(3e-6, 0.5 * RELIEF_LENGTH, root_relief_m=2e-6, root_length_m=1e-3))
    phases = np.arange(97) / 97
    ste = 1.5e-6 * np.cos(2 * np.pi * phases + 0.3)
    loads = np.array([0.3, 1.0, 2.5]) * LOAD
    result = static_transmission_error(PAIR, ISO, loads, modification=mod, phases=phases, unloaded_ste_m=ste)
    xi, contact = pair_positions(PAIR, phases)
    k_all = ISO.stiffness(xi - PAIR.contact_start_m)
    g_all = ste[None] + mod.deviation(PAIR, xi)
    for i, load in enumerate(loads):
        for n in range(phases.size):
            c = contact[:, n]
            expected = scalar_solve(k_all[c, n], g_all[c, n], load)
            assert result.delta_m[i, n] == pytest.approx(expected, rel=1e-12)
        assert np.sum(result.pair_loads_N[:, i], axis=0) == pytest.approx(np.full(phases.size, load), rel=1e-12)


def test_constant_stiffness_no_relief_is_the_rectangular_model_exactly():
    k1 = 3.6e8
    result = static_transmission_error(PAIR, ConstantPairStiffness(k1), LOAD)
    double = result.phase < PAIR.contact_ratio - 1.0
    assert np.all(result.delta_m[double] == LOAD / (2 * k1))
    assert np.all(result.delta_m[~double] == LOAD / k1)
    assert np.all(result.mesh_stiffness_N_per_m == np.where(double, 2 * k1, k1))
    # equal sharing
    assert np.all(result.pair_loads_N[:, double] == LOAD / 2)


def test_mesh_stiffness_is_the_slope_dN_ddelta():
    mod = ProfileModification(FlankRelief(5e-6, RELIEF_LENGTH), FlankRelief(5e-6, RELIEF_LENGTH))
    phases = np.arange(60) / 60
    h = 1.0
    res = static_transmission_error(PAIR, ISO, np.array([LOAD - h, LOAD, LOAD + h]), modification=mod, phases=phases)
    same_regime = (res.mesh_stiffness_N_per_m[0] == res.mesh_stiffness_N_per_m[2])
    assert same_regime.sum() > 40
    slope = 2 * h / (res.delta_m[2] - res.delta_m[0])
    assert slope[same_regime] == pytest.approx(res.mesh_stiffness_N_per_m[1][same_regime], rel=1e-7)


def test_jax_jit_matches_numpy():
    phases = np.arange(50) / 50
    xi, contact = pair_positions(PAIR, phases)
    k = ISO.stiffness(xi - PAIR.contact_start_m)
    g = ProfileModification(FlankRelief(4e-6, RELIEF_LENGTH)).deviation(PAIR, xi)
    ref = solve_static_contact(k, g, contact, LOAD)
    out = jax.jit(lambda k, g, c, n: solve_static_contact(k, g, c, n, jnp))(k, g, contact, LOAD)
    for a, b in zip(ref, out):
        np.testing.assert_allclose(np.asarray(b), a, rtol=1e-14, atol=0)


@st.composite
def contacts(draw):
    slots = draw(st.integers(1, 4))
    shape = (slots, draw(st.integers(1, 5)))
    k = np.array(draw(st.lists(st.floats(1e7, 1e9), min_size=slots * shape[1], max_size=slots * shape[1])))
    g = np.array(draw(st.lists(st.floats(-2e-5, 2e-5), min_size=slots * shape[1], max_size=slots * shape[1])))
    mask = np.array(draw(st.lists(st.booleans(), min_size=slots * shape[1], max_size=slots * shape[1])))
    mask = mask.reshape(shape)
    mask[0] = True  # at least one pair in contact
    return k.reshape(shape), g.reshape(shape), mask


@settings(max_examples=150, deadline=None)
@given(contacts(), st.floats(1.0, 1e5), st.floats(1.0001, 3.0))
def test_properties_loads_sum_nonnegative_and_monotone(data, load, factor):
    k, g, mask = data
    delta, loads, _ = solve_static_contact(k, g, mask, load)
    assert np.all(loads >= 0) and np.all(loads[~mask] == 0)
    np.testing.assert_allclose(loads.sum(axis=0), load, rtol=1e-10)
    for n in range(k.shape[1]):
        c = mask[:, n]
        # delta can be ~0 from cancelling gaps: the absolute part is rounding on the scale of
        # the gaps and of the deflection N/k
        scale = np.max(np.abs(g[c, n])) + load / np.min(k[c, n])
        assert delta[n] == pytest.approx(scalar_solve(k[c, n], g[c, n], load), rel=1e-12, abs=1e-13 * scale)
    delta_more, _, _ = solve_static_contact(k, g, mask, load * factor)
    assert np.all(delta_more > delta)


def test_harris_map_constant_stiffness_minimum_at_design_load():
    # Relief designed by the rule: C_a = single-pair deflection at the design load N_d / k1,
    # long relief (L_a = (Gamma - 1) p_b) on both tips: the TE is flat at N_d.
    k1 = 3.6e8
    relief = LOAD / k1
    mod = ProfileModification(FlankRelief(relief, RELIEF_LENGTH), FlankRelief(relief, RELIEF_LENGTH))
    loads = LOAD * np.linspace(0.25, 2.0, 36)  # contains 1.0 exactly at index 15
    p2p = harris_map(PAIR, ConstantPairStiffness(k1), loads, modification=mod)
    assert loads[np.argmin(p2p)] == pytest.approx(LOAD, rel=1e-12)
    assert p2p.min() < 1e-12 * relief
    unmodified = harris_map(PAIR, ConstantPairStiffness(k1), [LOAD])[0]
    assert unmodified == pytest.approx(LOAD / (2 * k1), rel=1e-12)


def test_harris_map_minimum_moves_with_relief_amount_iso_shape():
    # With the ISO parabola the rule (C_a = N_d / (c' b)) is no longer exact; the minimum
    # stays within 10 % of the design load and removes most of the unmodified p2p.
    loads = LOAD * np.linspace(0.2, 2.0, 91)
    minima = []
    for scale in (0.6, 1.0, 1.5):
        relief = scale * LOAD / ISO.peak_N_per_m
        mod = ProfileModification(FlankRelief(relief, RELIEF_LENGTH), FlankRelief(relief, RELIEF_LENGTH))
        p2p = harris_map(PAIR, ISO, loads, modification=mod)
        minima.append(loads[np.argmin(p2p)])
        if scale == 1.0:
            assert minima[-1] == pytest.approx(LOAD, rel=0.10)
            unmodified = harris_map(PAIR, ISO, [LOAD])[0]
            assert p2p.min() < 0.15 * unmodified
    assert minima[0] < minima[1] < minima[2]


# ----------------------------------------------------------------------------- torque tables


def test_rectangular_mesh_stiffness_is_ste_plus_load_over_k():
    # the paper's k(s) (k_max != 2 k_min), written out here on its own: delta = eps + N / k(s)
    k_max, k_min = 7.2e8, 4.519e8
    phases = np.arange(360) / 360
    ste = 2e-6 * np.cos(2 * np.pi * phases + 0.4) + 0.5e-6 * np.cos(4 * np.pi * phases)
    result = static_transmission_error(PAIR, RectangularMeshStiffness(k_max, k_min), LOAD, phases=phases,
                                       unloaded_ste_m=ste)
    k = np.where(phases < PAIR.contact_ratio - 1.0, k_max, k_min)
    np.testing.assert_allclose(result.delta_m, ste + LOAD / k, rtol=1e-13, atol=0)
    assert np.all(result.mesh_stiffness_N_per_m == k)
    double = phases < PAIR.contact_ratio - 1.0
    np.testing.assert_allclose(result.pair_loads_N[:, double], LOAD / 2, rtol=1e-13)  # equal sharing
    # k_max = 2 k1, k_min = k1 is the constant single-pair stiffness k1, exactly
    k1 = 3.6e8
    same = static_transmission_error(PAIR, RectangularMeshStiffness(2 * k1, k1), LOAD)
    constant = static_transmission_error(PAIR, ConstantPairStiffness(k1), LOAD)
    for a, b in zip(same, constant):
        assert np.array_equal(a, b)


def test_unloaded_ste_is_the_dynamic_models():
    from hbgear.build import build_model
    from hbgear.config import load_config

    example = Path(__file__).resolve().parent.parent / "examples" / "paper_table1.toml"
    model = build_model(load_config(example, ["mesh.ste_amplitude_um=[1.5, 0.4, 0.1]",
                                              "mesh.ste_phase_deg=[10.0, -70.0, 200.0]"]))
    phases = np.linspace(0.0, 1.0, 101)
    expected, _ = model.static_transmission_error(phases, 1.0)
    got = unloaded_ste(phases, model.ste_amplitude_m, model.ste_phase_rad)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-21)
    assert np.all(unloaded_ste(phases) == 0.0)


def test_loaded_te_table_is_one_static_solve_per_torque():
    mod = ProfileModification(FlankRelief(8e-6, RELIEF_LENGTH), FlankRelief(8e-6, RELIEF_LENGTH))
    soft = Iso6336PairStiffness(0.7 * ISO.peak_N_per_m, ISO.path_length_m, ISO.contact_ratio)
    torques = [150.0, 226.0]
    phases = np.arange(90) / 90
    table = loaded_te_table(PAIR, [soft, ISO], torques, modification=mod, phases=phases,
                            ste_amplitude_m=(1e-6,), ste_phase_rad=(0.3,))
    xi, contact = pair_positions(PAIR, phases)
    ste = 1e-6 * np.cos(2 * np.pi * phases + 0.3)
    for i, (model, torque) in enumerate(zip([soft, ISO], torques)):
        load = torque / PAIR.base_radius_pinion_m
        one = static_transmission_error(PAIR, model, load, modification=mod, phases=phases, unloaded_ste_m=ste)
        assert table.load_N[i] == load
        assert np.array_equal(table.delta_m[i], one.delta_m)
        assert np.array_equal(table.pair_loads_N[i], one.pair_loads_N)
        assert np.array_equal(table.mesh_stiffness_N_per_m[i], one.mesh_stiffness_N_per_m)
        assert table.p2p_m[i] == np.ptp(one.delta_m) and table.mean_m[i] == np.mean(one.delta_m)
        assert table.mesh_stiffness_mean_N_per_m[i] == np.mean(one.mesh_stiffness_N_per_m)
        expected_k = np.where(contact, model.stiffness(xi - PAIR.contact_start_m), 0.0)
        assert np.array_equal(table.pair_stiffness_N_per_m[i], expected_k)
    assert table.pair_stiffness_max_N_per_m.tolist() == [soft.peak_N_per_m, ISO.peak_N_per_m]
    np.testing.assert_allclose(table.position_m, xi - PAIR.contact_start_m, rtol=0, atol=1e-18)
    # one model for every torque
    shared = loaded_te_table(PAIR, ISO, torques, modification=mod, phases=phases)
    assert np.array_equal(shared.p2p_m, harris_map(PAIR, ISO, table.load_N, modification=mod, phases=phases))


def test_pair_stiffness_max_of_each_model():
    path = PAIR.contact_end_m - PAIR.contact_start_m
    assert pair_stiffness_max(ISO, PAIR) == ISO.peak_N_per_m  # mid-path, on the sample grid
    assert pair_stiffness_max(ConstantPairStiffness(3e8), PAIR) == 3e8
    assert pair_stiffness_max(RectangularMeshStiffness(7.2e8, 4.5e8), PAIR) == 4.5e8
    assert pair_stiffness_max(RectangularMeshStiffness(7.2e8, 3e8), PAIR) == 3.6e8
    # a peak between the uniform samples, at a table node; a node outside the path does not count
    peak_at = 0.123456789 * path
    table = TablePairStiffness((-0.01 * path, peak_at, path, 1.01 * path), (1e8, 3e8, 2e8, 9e8))
    assert pair_stiffness_max(table, PAIR) == 3e8
