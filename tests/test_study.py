"""`hbgear study` and hbgear.study: the [study] section, the samples, each row = the `hbgear frc` run
with the same --set values, failing samples as rows, resume after SIGKILL with a byte-identical
study.csv, the Dask path = the local path, load_study / to_dataframe."""

import csv
import json
import math
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import hbgear
from hbgear import cli
from hbgear.config import parse_config, read_toml
from hbgear.errors import ConfigError
from hbgear.studies import RECORD, draw_samples, sample_data, set_arguments

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "examples" / "paper_table1.toml"
#: a small, fast curve: linear model (exact monodromy), H = 8, a 2000 rpm sweep over the resonance
FAST = ['boundary.output="torques"', "solver.harmonics=8", "solver.time_samples=64", "sweep.speed_rpm_start=12000.0",
        "sweep.speed_rpm_stop=14000.0"]


def study_file(tmp_path: Path, study: str, name: str = "study.toml", mesh: str = "") -> Path:
    """The reference pair with the FAST settings written in, `mesh` lines and a [study] table."""
    text = EXAMPLE.read_text()
    text = text.replace('output = "spring"', 'output = "torques"').replace("harmonics = 32", "harmonics = 8")
    text = text.replace("time_samples = 1024", "time_samples = 64").replace("speed_rpm_start = 1000.0",
                                                                            "speed_rpm_start = 12000.0")
    text = text.replace("speed_rpm_stop = 20000.0", "speed_rpm_stop = 14000.0")
    if mesh:
        text = text.replace("ste_amplitude_um = []", "").replace("ste_phase_deg = []", "")
        text = text.replace("[mesh]\n", "[mesh]\n" + mesh + "\n")
    path = tmp_path / name
    path.write_text(text + "\n" + study)
    return path


def base_with(study: dict) -> dict:
    data = read_toml(EXAMPLE)
    data["study"] = study
    return data


def same(a, b) -> bool:
    """Equal, NaN equal to NaN."""
    return a == b or (isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b))


# ----------------------------------------------------------------------------- definition


@pytest.mark.parametrize("study, key, phrase", [
    ({"parameters": {"mesh.damping": [0.01]}}, 'study.parameters."mesh.damping"', "a key of [mesh]"),
    ({"parameters": {"meshes.damping_ratio": [0.01]}}, 'study.parameters."meshes.damping_ratio"', "config section"),
    ({"parameters": {"mesh.damping_ratio": 0.01}}, 'study.parameters."mesh.damping_ratio"', "non-empty list"),
    ({"parameters": {"mesh.damping_ratio": {"normal": [0.01, 0.001]}}}, 'study.parameters."mesh.damping_ratio"',
     'kind = "monte_carlo"'),
    ({"kind": "monte_carlo", "samples": 3, "parameters": {"friction.mu0": [0.1]}}, 'study.parameters."friction.mu0"',
     "choice"),
    ({"kind": "monte_carlo", "samples": 3, "parameters": {"friction.mu0": {"normal": [0.1, -1.0]}}},
     'study.parameters."friction.mu0"', "std >= 0"),
    ({"kind": "monte_carlo", "samples": 3, "parameters": {"friction.mu0": {"uniform": [0.2, 0.1]}}},
     'study.parameters."friction.mu0"', "low <= high"),
    ({"kind": "monte_carlo", "parameters": {"friction.mu0": {"uniform": [0.1, 0.2]}}}, "study.samples", "required"),
    ({"samples": 4, "parameters": {"friction.mu0": [0.1]}}, "study.samples", "monte_carlo"),
    ({"kind": "sweep", "parameters": {"friction.mu0": [0.1]}}, "study.kind", "grid"),
    ({"parameters": {"mesh.ste_amplitude_um": [[1.0]], "mesh.ste_amplitude_um[0]": [2.0]}},
     'study.parameters."mesh.ste_amplitude_um[0]"', "not varied already"),
    ({"parameters": {"study.kind": ["grid"]}}, 'study.parameters."study.kind"', "config section"),
    ({"parameters": {}}, "study.parameters", "[study.parameters]"),
    ({"parameter": {"friction.mu0": [0.1]}}, "study.parameter", "not a known key"),
])
def test_bad_study_sections_name_the_key(study, key, phrase):
    with pytest.raises(ConfigError) as err:
        parse_config(base_with(study))
    assert err.value.key == key and phrase in err.value.allowed


def test_both_spellings_of_a_dotted_key_and_the_round_trip():
    quoted = parse_config(base_with({"parameters": {"friction.mu0": [0.05, 0.1]}})).study
    nested = parse_config(base_with({"parameters": {"friction": {"mu0": [0.05, 0.1]}}})).study
    assert quoted == nested and quoted.parameters[0].key == "friction.mu0"
    mc = {"kind": "monte_carlo", "samples": 5, "seed": 3, "scheduler": "tcp://127.0.0.1:8786",
          "parameters": {"mesh.ste_amplitude_um[0]": {"normal": [1.0, 0.2]}, "friction.mu0": {"choice": [0.05, 0.1]}}}
    config = parse_config(base_with(mc))
    assert config.study.to_dict() == mc
    assert parse_config(config.to_dict()).study == config.study
    assert "study" not in parse_config(read_toml(EXAMPLE)).to_dict()  # no study: to_dict as before


def test_grid_order_and_monte_carlo_draws():
    grid = parse_config(base_with({"parameters": {"load.torque_pinion_Nm": [100.0, 200.0],
                                                  "mesh.damping_ratio": [0.01, 0.02, 0.03]}})).study
    samples = draw_samples(grid)
    assert [(s["load.torque_pinion_Nm"], s["mesh.damping_ratio"]) for s in samples] == [
        (100.0, 0.01), (100.0, 0.02), (100.0, 0.03), (200.0, 0.01), (200.0, 0.02), (200.0, 0.03)]

    def mc(seed, n=4000):
        return parse_config(base_with({"kind": "monte_carlo", "samples": n, "seed": seed, "parameters": {
            "friction.mu0": {"uniform": [0.05, 0.1]}, "mesh.damping_ratio": {"normal": [0.02, 0.005]},
            "load.torque_pinion_Nm": {"lognormal": [math.log(200.0), 0.1]},
            "friction.law": {"choice": ["coulomb", "arctan"]}}})).study

    draws = draw_samples(mc(1))
    again, other = draw_samples(mc(1)), draw_samples(mc(2))
    assert draws == again and draws != other
    n = len(draws)
    mu0 = np.array([s["friction.mu0"] for s in draws])
    zeta = np.array([s["mesh.damping_ratio"] for s in draws])
    torque = np.array([s["load.torque_pinion_Nm"] for s in draws])
    assert 0.05 <= mu0.min() and mu0.max() < 0.1
    assert abs(mu0.mean() - 0.075) < 4 * 0.05 / math.sqrt(12 * n)
    assert abs(zeta.mean() - 0.02) < 4 * 0.005 / math.sqrt(n) and abs(zeta.std() / 0.005 - 1) < 0.05
    assert abs(np.median(np.log(torque)) - math.log(200.0)) < 4 * 0.1 * 1.26 / math.sqrt(n)
    assert {s["friction.law"] for s in draws} == {"coulomb", "arctan"}
    assert all(isinstance(s["mesh.damping_ratio"], float) for s in draws)


def test_a_list_entry_sample_and_its_set_arguments_give_the_same_config():
    data = base_with({"parameters": {"mesh.ste_amplitude_um[1]": [0.25]}})
    data["mesh"] |= {"ste_amplitude_um": [1.0, 0.5], "ste_phase_deg": [0.0, 90.0]}
    assignments = [("mesh", "ste_amplitude_um", 1, 0.25), ("friction", "mu0", None, 0.07)]
    sample = parse_config(sample_data(data, assignments))
    assert sample.mesh.ste_amplitude_m == pytest.approx((1e-6, 0.25e-6), rel=1e-15)
    assert sample.friction.mu0 == 0.07 and sample.study.parameters == ()
    args = set_arguments(data, assignments)
    assert args == ["mesh.ste_amplitude_um=[1.0, 0.25]", "friction.mu0=0.07"]
    del data["study"]
    assert parse_config(data, args) == sample
    assert data["mesh"]["ste_amplitude_um"] == [1.0, 0.5]  # the base is not changed


def test_an_entry_beyond_the_base_list_is_bad_input_a_number_for_an_empty_list_is_accepted(tmp_path):
    path = study_file(tmp_path, '[study]\n[study.parameters]\n"mesh.ste_amplitude_um[0]" = [1.0]\n')
    with pytest.raises(ConfigError, match=r"ste_amplitude_um = \[1.0\]"):
        hbgear.study(path, workers=1, progress=False)
    # INTERFACE.md's form: a number drawn for the (empty) STE list is the one-entry list
    path = study_file(tmp_path, '[study]\nkind = "monte_carlo"\nsamples = 2\n[study.parameters]\n'
                      '"mesh.ste_amplitude_um" = { normal = [1.0, 0.2] }\n')
    result = hbgear.study(path, workers=1, progress=False)
    assert all(row["success"] for row in result.rows())


# ----------------------------------------------------------------------------- runs


def frc_record(tmp_path: Path, config: Path, sets: list[str], name: str) -> tuple[dict, list[dict]]:
    out = tmp_path / name
    argv = ["frc", str(config), "--out", str(out), "--no-progress"]
    for s in sets:
        argv += ["--set", s]
    assert cli.main(argv) == 0
    with (out / "frc.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    return json.loads((out / "frc.json").read_text()), rows


MONTE_CARLO = """[study]
kind = "monte_carlo"
samples = 4
seed = 4
[study.parameters]
"mesh.ste_amplitude_um[0]" = { normal = [1.0, 0.2] }
"mesh.damping_ratio" = { normal = [0.02, 0.02] }
"""


def test_each_row_is_the_frc_run_with_the_same_set_values(tmp_path, capsys):
    """Local processes (2 workers); sample 2 draws a negative damping ratio: a row with success 0."""
    config = study_file(tmp_path, MONTE_CARLO, mesh="ste_amplitude_um = [1.0]\nste_phase_deg = [30.0]")
    out = tmp_path / "study"
    assert cli.main(["study", str(config), "--out", str(out), "--workers", "2", "--no-progress"]) == 0
    assert "1 of 4 samples failed" in capsys.readouterr().err
    summary = json.loads((out / "study.json").read_text())
    assert summary["execution"] == {"mode": "processes", "workers": 2, "scheduler": None}
    assert {p.name for p in out.iterdir()} == {"study.csv", "study.json", "study.png"}
    with (out / "study.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert list(rows[0]) == ["sample", "mesh.ste_amplitude_um[0]", "mesh.damping_ratio", "peak_dte_p2p_um",
                             "peak_speed_rpm", "max_dynamic_factor", "unstable_zones", "success", "unstable_points",
                             "folds", "period_doublings", "points", "status", "message"]
    assert [r["success"] for r in rows] == ["1", "1", "0", "1"]
    assert rows[2]["status"] == "invalid" and rows[2]["message"].startswith("mesh.damping_ratio = -0.006")
    assert rows[2]["peak_dte_p2p_um"] == "nan"
    for row, record in zip(rows, summary["records"]):
        if row["success"] == "0":
            continue
        assert record["set"][0].startswith("mesh.ste_amplitude_um=[") and record["set"][1].startswith(
            "mesh.damping_ratio=")
        frc, curve = frc_record(tmp_path, config, record["set"], f"frc{row['sample']}")
        n = frc["points"]
        assert int(row["points"]) == n and int(row["unstable_points"]) == frc["stability"]["unstable_points"]
        assert int(row["unstable_zones"]) == len(frc["stability"]["unstable_zones"])
        assert int(row["folds"]) == len(frc["folds"]) and int(row["period_doublings"]) == len(frc["period_doubling"])
        for mine, theirs in [(row["peak_dte_p2p_um"], frc["peak"]["dte_p2p_um"]),
                             (row["peak_speed_rpm"], frc["peak"]["speed_rpm"]),
                             (row["max_dynamic_factor"], max(float(r["dynamic_factor"]) for r in curve[:n]))]:
            assert float(mine) == pytest.approx(theirs, rel=1e-9, abs=0)
    # each worker process compiled once: its later samples reuse the compiled programs
    records = summary["records"]
    per_worker = {}
    for r in records:
        per_worker.setdefault(r["worker"], []).append(r["compile_seconds"])
    assert len(per_worker) == 2
    for seconds in per_worker.values():
        if len(seconds) > 1:
            assert max(seconds[1:]) < 0.2 * seconds[0]
    assert 0.0 < summary["timings_s"]["compile_fraction"] < 1.0


GRID = """[study]
[study.parameters]
"load.torque_pinion_Nm" = [113.0, 150.0, 200.0, 226.0, 300.0, 339.0]
"""


@pytest.fixture(scope="module")
def grid_run(tmp_path_factory):
    """The 6-sample torque grid, uninterrupted, in this process."""
    tmp = tmp_path_factory.mktemp("grid")
    config = study_file(tmp, GRID)
    result = hbgear.study(config, out=tmp / "whole", workers=1, progress=False)
    return config, tmp / "whole", result


def test_a_linear_model_response_scales_with_the_torque(grid_run):
    """Formulation A, LTV, constant torques: every force is proportional to the load, so the DTE is
    (an independent check that each sample runs its own config)."""
    _, _, result = grid_run
    torque, peak = result["load.torque_pinion_Nm"], result["peak_dte_p2p_um"]
    assert result.success.all()
    np.testing.assert_allclose(peak / torque, peak[0] / torque[0], rtol=1e-9)
    np.testing.assert_allclose(result["peak_speed_rpm"], result["peak_speed_rpm"][0], rtol=1e-9)
    np.testing.assert_allclose(result.max_dynamic_factor, result.max_dynamic_factor[0], rtol=1e-9)


def _journal_records(path: Path) -> int:
    try:
        return max(len(path.read_text().splitlines()) - 1, 0)
    except FileNotFoundError:
        return 0


def test_killed_study_resumes_to_the_same_csv(grid_run, tmp_path, monkeypatch, capsys):
    config, whole, _ = grid_run
    out = tmp_path / "killed"
    argv = ["study", str(config), "--out", str(out), "--workers", "1", "--no-progress"]
    proc = subprocess.Popen([sys.executable, "-m", "hbgear", *argv], cwd=ROOT, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE)
    deadline = time.monotonic() + 300
    while _journal_records(out / RECORD) < 2 and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert proc.returncode == -signal.SIGKILL, proc.stderr.read().decode()
    kept = _journal_records(out / RECORD)
    assert 2 <= kept < 6 and not (out / "study.csv").exists()

    # the record is refused without --resume, and a record of another study is never resumed
    assert cli.main(argv) == 2
    assert "--resume to continue it or --fresh" in capsys.readouterr().err
    assert cli.main([*argv, "--resume", "--set", "mesh.damping_ratio=0.02"]) == 2
    assert "a record of another study" in capsys.readouterr().err

    from hbgear import studies

    calls = []
    real = studies.run_sample

    def counting(base, assignments, options):
        calls.append(assignments[0][3])
        return real(base, assignments, options)

    monkeypatch.setattr(studies, "run_sample", counting)
    assert cli.main([*argv, "--resume"]) == 0
    assert len(calls) == 6 - kept  # nothing recomputed
    assert (out / "study.csv").read_bytes() == (whole / "study.csv").read_bytes()
    assert not (out / RECORD).exists()
    summary = json.loads((out / "study.json").read_text())
    assert summary["timings_s"]["samples_resumed"] == kept
    assert summary["timings_s"]["samples_computed"] == 6 - kept


def test_an_interrupted_task_keeps_what_finished(grid_run, tmp_path, monkeypatch):
    config, whole, _ = grid_run
    from hbgear import studies

    real, calls = studies.run_sample, []

    def interrupted(base, assignments, options):
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return real(base, assignments, options)

    monkeypatch.setattr(studies, "run_sample", interrupted)
    with pytest.raises(KeyboardInterrupt):
        hbgear.study(config, out=tmp_path, workers=1, progress=False)
    assert _journal_records(tmp_path / RECORD) == 2
    calls.clear()
    monkeypatch.setattr(studies, "run_sample", real)
    result = hbgear.study(config, out=tmp_path, workers=1, progress=False, resume=True)
    assert result.info["timings_s"]["samples_computed"] == 4
    assert (tmp_path / "study.csv").read_bytes() == (whole / "study.csv").read_bytes()
    # --fresh starts again
    (tmp_path / RECORD).write_text((tmp_path / "study.csv").read_text())
    assert hbgear.study(config, out=tmp_path, workers=1, progress=False, fresh=True).info["timings_s"][
        "samples_computed"] == 6


def test_load_study_and_dataframes(grid_run, monkeypatch):
    _, whole, result = grid_run
    loaded = hbgear.load_study(whole)
    assert loaded.keys == result.keys and len(loaded) == len(result) == 6
    assert all(all(same(a[k], b[k]) for k in a) and a.keys() == b.keys() for a, b in zip(loaded.rows(), result.rows()))
    assert loaded.records[0]["set"] == ["load.torque_pinion_Nm=113.0"]
    assert loaded.info["execution"]["mode"] == "in-process"
    csv_only = whole.parent / "csv_only"
    csv_only.mkdir()
    (csv_only / "study.csv").write_bytes((whole / "study.csv").read_bytes())
    again = hbgear.load_study(csv_only / "study.csv")
    assert all(all(same(a[k], b[k]) for k in a) for a, b in zip(again.rows(), result.rows()))
    monkeypatch.setitem(sys.modules, "pandas", None)
    with pytest.raises(ImportError, match="pip install pandas"):
        result.to_dataframe()


def test_to_dataframe_with_pandas(grid_run):
    pandas = pytest.importorskip("pandas")
    _, _, result = grid_run
    frame = result.to_dataframe()
    assert list(frame.columns) == list(result.columns) and len(frame) == 6
    np.testing.assert_array_equal(frame["peak_dte_p2p_um"].to_numpy(), result.peak_dte_p2p_um)
    assert isinstance(frame, pandas.DataFrame)


FAILING = """[study]
[study.parameters]
"friction.model" = ["LTV", "NLTV"]
"sweep.max_points" = [6, 400]
"""


def test_dask_path_equals_local_path_and_failures_are_rows(tmp_path):
    """NLTV with constant torques is refused by the physics checks; 6 points stop the continuation."""
    distributed = pytest.importorskip("dask.distributed")
    config = study_file(tmp_path, FAILING)
    local = hbgear.study(config, out=tmp_path / "local", workers=1, progress=False, curves=True)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cluster:
        remote = hbgear.study(config, out=tmp_path / "dask", scheduler=cluster.scheduler_address, progress=False,
                              curves=True)
    assert remote.info["execution"]["mode"] == "dask"
    assert (tmp_path / "dask" / "study.csv").read_bytes() == (tmp_path / "local" / "study.csv").read_bytes()
    assert [r["status"] for r in local.records] == ["max_points", "success", "invalid", "invalid"]
    assert list(local.success) == [False, True, False, False]
    assert "NLTV" in local.records[2]["message"] and local.records[0]["points"] == 6
    assert local.curve(1)["speed_rpm"][-1] == 14000.0
    assert (tmp_path / "dask" / "curves" / "sample-0001" / "frc.csv").read_bytes() == (
        tmp_path / "local" / "curves" / "sample-0001" / "frc.csv").read_bytes()


def test_cli_bad_inputs_exit_2(tmp_path, capsys, monkeypatch):
    plain = ["study", str(EXAMPLE), "--out", str(tmp_path / "o")]
    assert cli.main(plain) == 2
    assert "[study.parameters]" in capsys.readouterr().err
    config = study_file(tmp_path, GRID)
    assert cli.main(["study", str(config), "--resume", "--fresh"]) == 2
    assert cli.main(["study", str(config), "--workers", "0"]) == 2
    monkeypatch.setitem(sys.modules, "dask.distributed", None)
    assert cli.main(["study", str(config), "--scheduler", "tcp://127.0.0.1:1", "--out", str(tmp_path / "o")]) == 2
    assert "install hbgear[distributed]" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_frc_curve_is_the_frc_path_and_its_dataframe(monkeypatch):
    from hbgear.api import frc_curve
    from hbgear.gear.response import COLUMNS

    curve = frc_curve(hbgear.load_config(EXAMPLE, FAST), progress=False)
    assert curve.success and curve.speed_rpm[0] == 12000.0 and curve.speed_rpm[curve.points - 1] == 14000.0
    assert curve.harmonics == 8 and curve.response.hb.samples == 64
    try:
        import pandas  # noqa: F401
    except ImportError:
        pass
    else:
        frame = curve.to_dataframe()
        assert list(frame.columns) == list(COLUMNS) and len(frame) == len(curve)
        np.testing.assert_array_equal(frame["dte_p2p_um"].to_numpy(), curve.dte_p2p_um)
    monkeypatch.setitem(sys.modules, "pandas", None)
    with pytest.raises(ImportError, match="pip install pandas"):
        curve.to_dataframe()


def test_a_number_for_a_one_entry_list_key_is_that_list():
    """INTERFACE.md's Monte Carlo example draws "mesh.ste_amplitude_um" = { normal = [...] }: with a
    base list of at most one entry a drawn number x is the list [x] (the first mesh order)."""
    from hbgear.studies import sample_data

    assert sample_data({"mesh": {}}, [("mesh", "ste_amplitude_um", None, 1.25)])["mesh"]["ste_amplitude_um"] == [1.25]
    assert sample_data({"mesh": {"ste_amplitude_um": [0.5]}}, [("mesh", "ste_amplitude_um", None, 2.0)])[
        "mesh"]["ste_amplitude_um"] == [2.0]
    assert sample_data({"mesh": {}}, [("mesh", "ste_amplitude_um", None, [1.0, 2.0])])["mesh"]["ste_amplitude_um"] == [
        1.0, 2.0]
