"""End-to-end runs of `hbgear solve` and `hbgear validate`: the files and columns of INTERFACE.md."""

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from hbgear import cli

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "paper_table1.toml"
SMALL = ["--set", "solver.harmonics=16", "--set", "solver.time_samples=256"]
SOLUTION_KEYS = {
    "speed_rpm", "dte_mean_um", "dte_rms_um", "dte_p2p_um", "dynamic_factor", "mean_input_power_W",
    "mean_output_power_W", "mean_power_loss_W", "mean_friction_loss_W", "mean_mesh_power_W",
    "max_abs_floquet",
}
VALIDATION_HEADER = [
    "speed_rpm", "hb_dte_rms_um", "ti_dte_rms_um", "hb_dte_p2p_um", "ti_dte_p2p_um", "rel_diff_rms", "rel_diff_p2p",
]


def mean_abs_linear(a, b, lo, hi):
    """``int_lo^hi |a + b s| ds`` in closed form (the sign changes once, at ``s = -a/b``)."""
    root = float(np.clip(-a / b, lo, hi))

    def part(left, right):
        return abs(a * (right - left) + 0.5 * b * (right * right - left * left))

    return part(lo, root) + part(root, hi)


def quasi_static_friction_loss_W(model, omega):
    """``mu0 N <sum_j sigma_j |V_s,j|>`` at nominal sliding, from the geometry alone: two pairs
    (shares 1/2) for ``s < Gamma - 1``, then one; ``V_s = xi_p (W_p + W_g) - L W_g``,
    ``xi_p = x_A + p_b (s + k)`` for the pair that entered ``k`` mesh periods ago."""
    wp, wg = omega, omega * model.teeth_pinion / model.teeth_gear
    g1 = model.contact_ratio - 1.0

    def vs(k):
        a = (model.contact_start_m + model.base_pitch_m * k) * (wp + wg) - model.line_of_action_m * wg
        return a, model.base_pitch_m * (wp + wg)

    sliding = 0.5 * (mean_abs_linear(*vs(0), 0.0, g1) + mean_abs_linear(*vs(1), 0.0, g1)) + mean_abs_linear(*vs(0), g1, 1.0)
    return 0.1 * model.normal_load_N * sliding


@pytest.mark.parametrize("model_name", ["LTV", "NLTV"])
def test_solve_writes_solution_with_balanced_powers(tmp_path, model_name):
    """The powers of solution.json and its Floquet multipliers, against independent values.

    Spring boundary without damping of its own (the example). Averaging the output equation,
    ``<T_out> = R_bg <F_2>``, and ``<k_u (u + u_s) u'> = 0`` over a period, give the mean net power
    ``input - output = -<T_fp> W_p - <T_fg> W_g``: for LTV-A, whose friction is the fixed
    quasi-static ``mu0 sgn(V_s) sigma_j N``, that is exactly ``mu0 N <sum_j sigma_j |V_s,j|>``
    at nominal sliding (computed here from the geometry), whatever the vibration.
    """
    from hbgear.build import build_model
    from hbgear.config import load_config
    from hbgear.gear.monodromy import monodromy_variational, multipliers_linear
    from hbgear.gear.solve import rpm_to_rad_s, solve_periodic

    out = tmp_path / "solve"
    argv = ["solve", str(EXAMPLE), "--speed", "3000", *SMALL, "--set", f"friction.model='{model_name}'", "--out", str(out)]
    assert cli.main(argv) == 0
    data = json.loads((out / "solution.json").read_text())
    assert SOLUTION_KEYS <= set(data)
    assert data["speed_rpm"] == pytest.approx(3000.0)
    model = build_model(load_config(EXAMPLE, [f"friction.model='{model_name}'"]))
    omega = rpm_to_rad_s(3000.0)
    # periodicity: <theta_p'> = 0, so the input power is T_p W_p
    assert data["mean_input_power_W"] == pytest.approx(226.0 * omega, rel=1e-13)
    # MODEL.md section 4: loss = friction loss + <F_mesh delta'>; exact for LTV (measured 3e-15); NLTV's
    # AFT with the jumps at entry/exit corrected errs at O(1/N^2): 8.4e-6 measured at N = 256
    loss = data["mean_power_loss_W"]
    imbalance = abs(loss - data["mean_friction_loss_W"] - data["mean_mesh_power_W"]) / loss
    assert imbalance < (1e-12 if model_name == "LTV" else 2e-5)
    if model_name == "LTV":
        assert loss == pytest.approx(quasi_static_friction_loss_W(model, omega), rel=1e-12)
        assert data["mean_friction_loss_W"] != pytest.approx(loss, rel=1e-4)  # the vibration does enter here
    # multipliers: the largest is the undamped soft mode, against the exact monodromy (LTV) or the
    # variational equations (NLTV); Hill's method at H = 16 resolves it to 4e-14 (LTV) / 8e-9 (NLTV) (its mesh-mode pair
    # only to ~6e-4 (LTV) / 7e-3 (NLTV, N = 256), the truncation at 3000 rpm: tests/test_hill.py)
    hill = np.array([complex(*m) for m in data["floquet_multipliers"]])
    if model_name == "LTV":
        exact = multipliers_linear(model, omega)
    else:
        solution = solve_periodic(model, omega, harmonics=16, samples=256)
        exact = np.linalg.eigvals(monodromy_variational(model, solution, omega))
    soft = np.array([complex(*m) for m in data["neutral_soft_mode_multipliers"]])
    soft_exact = exact[np.argsort(-np.abs(exact))][:2]
    close = 1e-12 if model_name == "LTV" else 2e-8  # measured 4e-14 / 7.9e-9 (NLTV: the AFT's N = 256)
    assert soft.size == 2 and np.abs(np.sort_complex(soft) - np.sort_complex(soft_exact)).max() < close
    assert data["max_abs_floquet"] == pytest.approx(np.abs(soft_exact).max(), abs=close)
    assert hill.size > 0 and np.abs(hill).max() <= data["max_abs_floquet"] + 1e-15  # over all multipliers
    # LTV: |mult| = 1 - 3.4e-14; NLTV friction damps the mode, 1 - 2.9e-6
    assert (abs(1 - data["max_abs_floquet"]) < 1e-12) if model_name == "LTV" else (1e-6 < 1 - data["max_abs_floquet"] < 1e-5)
    assert data["stable"] is True
    assert (out / "harmonics.csv").exists() and (out / "waveform.csv").exists()


@pytest.mark.parametrize("boundary", ["spring", "reaction"])
def test_validate_agrees_with_time_integration(tmp_path, boundary):
    out = tmp_path / "validate"
    argv = ["validate", str(EXAMPLE), "--speed", "3000", *SMALL, "--set", "friction.model='LTV'",
            "--set", f"boundary.output='{boundary}'", "--out", str(out)]
    assert cli.main(argv) == 0
    with open(out / "validation.csv", newline="") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == VALIDATION_HEADER
    assert len(rows) == 2
    values = dict(zip(rows[0], map(float, rows[1])))
    assert values["speed_rpm"] == pytest.approx(3000.0)
    assert abs(values["rel_diff_rms"]) < 1e-3 and abs(values["rel_diff_p2p"]) < 1e-3
    assert (out / "validation.png").stat().st_size > 0
    if boundary == "spring":  # the gate: a tolerance below the difference -> exit 3, outputs still written
        (out / "validation.csv").unlink()
        tight = max(abs(values["rel_diff_rms"]), abs(values["rel_diff_p2p"])) / 2
        assert cli.main(argv + ["--tolerance", f"{tight:.3e}"]) == 3
        with open(out / "validation.csv", newline="") as fh:
            assert list(csv.reader(fh))[1] == rows[1]


@pytest.mark.parametrize("model", ["LTV", "NLTV"])  # exact monodromy / Hill's method
def test_frc_writes_every_floquet_multiplier(tmp_path, model):
    out = tmp_path / "frc"
    argv = ["frc", str(EXAMPLE), "--no-progress", "--out", str(out), "--set", "solver.harmonics=8",
            "--set", "solver.time_samples=64", "--set", f"friction.model='{model}'", "--set", "friction.law='arctan'",
            "--set", "sweep.speed_rpm_start=12000.0", "--set", "sweep.speed_rpm_stop=12600.0"]
    assert cli.main(argv) == 0
    with open(out / "frc.csv", newline="") as fh:
        curve = np.array(list(csv.reader(fh))[1:], dtype=float)
    with open(out / "floquet.csv", newline="") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["row", "speed_rpm", "index", "multiplier_re", "multiplier_im", "multiplier_abs"]
    table = np.array(rows[1:], dtype=float)
    point = table[:, 0].astype(int)
    assert np.array_equal(np.unique(point), np.arange(len(curve)))  # every point, none else
    assert np.all(np.bincount(point) == 4)  # 2n multipliers, n = 2 (DTE and the soft output mode)
    assert table[:, 1] == pytest.approx(curve[point, 0], rel=1e-14)
    assert table[:, 5] == pytest.approx(np.hypot(table[:, 3], table[:, 4]), rel=1e-12)
    first = table[:, 2] == 0  # sorted by modulus: index 0 is the largest, the frc.csv column
    assert table[first, 5] == pytest.approx(curve[:, 6], rel=1e-12)
    assert np.all(np.diff(table[:, 5].reshape(-1, 4), axis=1) <= 0)


def test_unstable_zone_between_curve_points_is_found():
    """The LTV-A pair has a period-doubling zone near 3800 rpm narrower than a curve step there."""
    from hbgear.build import build_model
    from hbgear.gear.response import unstable_zones
    from hbgear.config import load_config
    from hbgear.gear.solve import rpm_to_rad_s
    from hbgear.gear.monodromy import multipliers_linear

    model = build_model(load_config(EXAMPLE))
    around = rpm_to_rad_s(np.array([3791.5, 3819.7]))  # two stable curve points straddling the zone
    assert all(np.max(np.abs(m)) <= 1 + 1e-9 for m in multipliers_linear(model, around))
    zones = unstable_zones(model, around, subdivisions=12)
    assert len(zones) == 1
    zone = zones[0]
    assert zone["between_curve_points"] and zone["leaves_through"] == "-1"
    assert 3791.5 < zone["speed_rpm_from"] < zone["speed_rpm_to"] < 3819.7
    assert zone["resolution_rpm"] == pytest.approx((3819.7 - 3791.5) / 12, rel=1e-6)
    inside = multipliers_linear(model, rpm_to_rad_s(np.array([zone["speed_rpm_from"], zone["speed_rpm_to"]])))
    assert all(np.max(np.abs(m)) > 1 + 1e-9 for m in inside)
    assert unstable_zones(model, rpm_to_rad_s(np.array([3000.0, 3100.0]))) == []


def test_zone_labels_how_the_multiplier_leaves():
    from hbgear.engine.stability import leaves_through as _leaves_through

    assert _leaves_through(complex(-1.02, 0.0)) == "-1"
    assert _leaves_through(complex(1.02, 0.0)) == "+1"
    assert _leaves_through(complex(0.6, 0.9)) == "complex"  # a complex pair is neither +1 nor -1
