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


@pytest.mark.parametrize("model", ["LTV", "NLTV"])
def test_solve_writes_solution_with_balanced_powers(tmp_path, model):
    out = tmp_path / "solve"
    argv = ["solve", str(EXAMPLE), "--speed", "3000", *SMALL, "--set", f"friction.model='{model}'", "--out", str(out)]
    assert cli.main(argv) == 0
    data = json.loads((out / "solution.json").read_text())
    assert SOLUTION_KEYS <= set(data)
    assert data["speed_rpm"] == pytest.approx(3000.0)
    # MODEL.md section 4: input - output = friction loss + mean mesh power
    loss = data["mean_input_power_W"] - data["mean_output_power_W"]
    assert loss == pytest.approx(data["mean_power_loss_W"], rel=1e-12)
    # exact for LTV; NLTV's friction jumps at the pitch point alias at O(1/N) in the AFT (N = 256 here)
    imbalance_W = abs(loss - data["mean_friction_loss_W"] - data["mean_mesh_power_W"])
    assert imbalance_W < (1e-8 if model == "LTV" else 1e-3 * loss)
    assert data["mean_friction_loss_W"] > 0.0
    # the example's soft output mode is undamped: its multipliers sit on the unit circle
    assert 0.9 < data["max_abs_floquet"] <= 1.0 + 1e-9
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
    from hbgear.cli.frc import unstable_zones
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
    from hbgear.cli.frc import _leaves_through

    assert _leaves_through(complex(-1.02, 0.0)) == "-1"
    assert _leaves_through(complex(1.02, 0.0)) == "+1"
    assert _leaves_through(complex(0.6, 0.9)) == "complex"  # a complex pair is neither +1 nor -1
