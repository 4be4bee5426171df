"""End-to-end runs of `hbgear solve` and `hbgear validate`: the files and columns of INTERFACE.md."""

import csv
import json
from pathlib import Path

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
