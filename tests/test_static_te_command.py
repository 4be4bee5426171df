"""`hbgear static-te`: files and columns, values against the library and against independent
closed forms, the Harris map of the example, one-line errors, a light `--help`."""

import ast
import csv
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from hbgear import cli
from hbgear.build import build_model, build_tooth_contact
from hbgear.config import load_config
from hbgear.gear.contact import iso6336_stiffness, loaded_te_table

ROOT = Path(__file__).resolve().parent.parent
PAPER = ROOT / "examples" / "paper_table1.toml"
ISO_EXAMPLE = ROOT / "examples" / "iso_tip_relief.toml"
HEAD = ["torque_pinion_Nm", "mesh_phase", "position_mm", "loaded_te_um", "mesh_stiffness_MN_per_m",
        "pair_load_N_1", "pair_load_N_2", "pair_stiffness_MN_per_m_1", "pair_stiffness_MN_per_m_2"]
SUMMARY = {"torque_pinion_Nm", "normal_load_N", "loaded_te_p2p_um", "loaded_te_mean_um",
           "mesh_stiffness_mean_MN_per_m", "pair_stiffness_max_MN_per_m"}
NO_RELIEF = [f"--set=profile.{flank}_tip_relief_um=0.0" for flank in ("pinion", "gear")]


def run(capsys, *argv):
    status = cli.main(["static-te", *map(str, argv)])
    captured = capsys.readouterr()
    return status, captured.out, captured.err


def read_csv(path):
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    return rows[0], np.array(rows[1:], dtype=float)


def test_rectangular_is_ste_plus_load_over_k(tmp_path, capsys):
    out = tmp_path / "o"
    ste = ["--set", "mesh.ste_amplitude_um=[1.5, 0.3]", "--set", "mesh.ste_phase_deg=[20.0, 0.0]"]
    status, stdout, err = run(capsys, PAPER, "--out", out, *ste)
    assert status == 0 and err == "" and str(out) in stdout
    assert sorted(p.name for p in out.iterdir()) == ["static_te.csv", "static_te.json", "static_te.png"]
    header, rows = read_csv(out / "static_te.csv")
    assert header == HEAD and rows.shape == (720, len(HEAD))
    # independent route: the dynamic model's own k(s) and unloaded STE
    model = build_model(load_config(PAPER, [s for s in ste if s != "--set"]))
    s = rows[:, 1]
    np.testing.assert_array_equal(s, np.arange(720) / 720)
    k = model.mesh_stiffness(s)
    eps, _ = model.static_transmission_error(s, 1.0)
    load = 226.0 / model.base_radius_pinion_m
    np.testing.assert_allclose(rows[:, 3], 1e6 * (eps + load / k), rtol=1e-13)
    np.testing.assert_allclose(rows[:, 4], 1e-6 * k, rtol=1e-15)
    in_contact = s[:, None] + np.arange(2)[None] < model.contact_ratio
    np.testing.assert_allclose(rows[:, 5:7], load * in_contact / in_contact.sum(axis=1, keepdims=True), rtol=1e-13)
    np.testing.assert_allclose(rows[:, 2], 1e3 * model.base_pitch_m * s, rtol=1e-12, atol=1e-12)
    data = json.loads((out / "static_te.json").read_text())
    assert SUMMARY <= set(data) and data["stiffness_model"] == "rectangular"
    assert not any(key.startswith("iso6336") for key in data)
    assert data["loaded_te_p2p_um"] == pytest.approx(1e6 * np.ptp(eps + load / k), rel=1e-12)
    assert data["mesh_stiffness_mean_MN_per_m"] == pytest.approx(1e-6 * np.mean(k), rel=1e-14)
    assert data["pair_stiffness_max_MN_per_m"] == pytest.approx(1e-6 * model.k_min_N_per_m, rel=1e-15)
    assert data["config"]["mesh"]["ste_amplitude_um"] == [1.5, 0.3]
    assert data["geometry"]["contact_ratio"] == pytest.approx(1.433, rel=1e-12)
    assert len(data["torques"]) == 1 and data["torques"][0]["loaded_te_p2p_um"] == data["loaded_te_p2p_um"]


def write_table_config(tmp_path, rows):
    """A reference-pair config with a pair_table model reading `rows` (position_mm, stiffness)."""
    folder = tmp_path / "cfg"
    folder.mkdir(exist_ok=True)
    (folder / "pair.csv").write_text("position_mm,stiffness_MN_per_m\n" + "".join(f"{x},{k}\n" for x, k in rows))
    text = PAPER.read_text().replace('k_max_MN_per_m = 720.0', 'stiffness_model = "pair_table"').replace(
        "k_mean_MN_per_m = 568.0", 'pair_stiffness_file = "pair.csv"')
    (folder / "c.toml").write_text(text)
    return folder / "c.toml"


def path_mm():
    contact = build_tooth_contact(load_config(PAPER))
    return 1e3 * (contact.geometry.contact_end_m - contact.geometry.contact_start_m), contact.geometry


def test_constant_pair_table_is_load_over_k(tmp_path, capsys, monkeypatch):
    # k_pair = k1 along the whole path: N/(2 k1) in double contact, N/k1 in single contact
    length, pair = path_mm()
    config = write_table_config(tmp_path, [(0.0, 300.0), (length, 300.0)])
    monkeypatch.chdir(tmp_path)  # the table is found next to the config, not here
    status, _, err = run(capsys, config, "--out", tmp_path / "o", "--torque", "100")
    assert status == 0, err
    header, rows = read_csv(tmp_path / "o" / "static_te.csv")
    assert header == HEAD and np.all(rows[:, 0] == 100.0)
    load, k1 = 100.0 / pair.base_radius_pinion_m, 300e6
    double = rows[:, 1] < pair.contact_ratio - 1.0
    np.testing.assert_allclose(rows[:, 3], 1e6 * load / np.where(double, 2 * k1, k1), rtol=1e-14)
    np.testing.assert_allclose(rows[double, 5:7], load / 2, rtol=1e-14)
    data = json.loads((tmp_path / "o" / "static_te.json").read_text())
    assert data["pair_stiffness_max_MN_per_m"] == pytest.approx(300.0, rel=1e-15)
    assert data["config"]["mesh"]["pair_stiffness_file"] == str(config.parent / "pair.csv")


def test_iso_example_harris_map_has_its_minimum_at_the_design_torque(tmp_path, capsys):
    out = tmp_path / "o"
    status, _, err = run(capsys, ISO_EXAMPLE, "--out", out, "--torque", "150", "--torque", "226", "--torque", "300")
    assert status == 0, err
    assert {p.name for p in out.iterdir()} == {"static_te.csv", "static_te.json", "static_te.png", "harris.csv",
                                              "harris.png"}
    header, harris = read_csv(out / "harris.csv")
    assert header == ["torque_pinion_Nm", "loaded_te_p2p_um"] and harris[:, 0].tolist() == [150.0, 226.0, 300.0]
    assert np.argmin(harris[:, 1]) == 1  # relief designed for 226 N m
    # the files hold the library's numbers
    cfg = load_config(ISO_EXAMPLE)
    contacts = [build_tooth_contact(cfg, t) for t in (150.0, 226.0, 300.0)]
    table = loaded_te_table(contacts[0].geometry, [c.pair_stiffness for c in contacts], [150.0, 226.0, 300.0],
                            modification=contacts[0].modification)
    assert harris[:, 1].tolist() == (1e6 * table.p2p_m).tolist()
    header, rows = read_csv(out / "static_te.csv")
    assert header == HEAD and rows.shape == (3 * 720, len(HEAD))
    np.testing.assert_array_equal(rows[:, 3].reshape(3, 720), 1e6 * table.delta_m)
    np.testing.assert_array_equal(rows[:, 5:7].reshape(3, 720, 2), np.moveaxis(table.pair_loads_N, 1, 2))
    # loads balance N at every phase
    np.testing.assert_allclose(rows[:, 5:7].sum(axis=1), np.repeat(table.load_N, 720), rtol=1e-12)
    # the relief removes most of the unmodified TE at the design torque
    status, _, _ = run(capsys, ISO_EXAMPLE, "--out", tmp_path / "plain", *NO_RELIEF)
    plain = json.loads((tmp_path / "plain" / "static_te.json").read_text())
    assert harris[1, 1] < 0.15 * plain["loaded_te_p2p_um"]
    assert not (tmp_path / "plain" / "harris.csv").exists()
    # ISO numbers, independently from the standard's formula; the top level is the first torque
    data = json.loads((out / "static_te.json").read_text())
    pair = contacts[0].geometry
    iso = iso6336_stiffness((25, 31), (0.0, 0.0), pair.contact_ratio, rack_dedendum_coefficient=(1.25, 1.25))
    assert data["torque_pinion_Nm"] == 150.0 and [r["torque_pinion_Nm"] for r in data["torques"]] == [150, 226, 300]
    for record in data["torques"]:
        assert SUMMARY <= set(record)
        assert record["iso6336_c_prime_N_per_mm_um"] == pytest.approx(iso.c_prime_N_per_mm_um, rel=1e-15)
        assert record["iso6336_c_gamma_alpha_N_per_mm_um"] == pytest.approx(iso.c_gamma_alpha_N_per_mm_um, rel=1e-15)
        assert record["pair_stiffness_max_MN_per_m"] == pytest.approx(iso.c_prime_N_per_mm_um * 20.0, rel=1e-14)
    assert data["config"]["profile"]["pinion_tip_relief_um"] == 24.0


def test_example_relief_follows_the_documented_rule():
    # C_a = N_d / (c' b), L_a = (Gamma - 1) p_b at [load] torque_pinion_Nm, to the digits written
    contact = build_tooth_contact(load_config(ISO_EXAMPLE))
    pair, profile = contact.geometry, load_config(ISO_EXAMPLE).profile
    amount = 226.0 / pair.base_radius_pinion_m / contact.pair_stiffness.peak_N_per_m
    length = (pair.contact_ratio - 1.0) * pair.base_pitch_m
    for flank in ("pinion", "gear"):
        assert getattr(profile, f"{flank}_tip_relief_m") == pytest.approx(amount, abs=0.05e-6)
        assert getattr(profile, f"{flank}_tip_relief_length_m") == pytest.approx(length, abs=0.005e-3)


BAD_TABLES = {
    "not increasing": lambda n: [(0.0, 300.0), (n / 2, 300.0), (n / 4, 300.0), (n, 300.0)],
    "short": lambda n: [(0.0, 300.0), (0.9 * n, 300.0)],
    "negative stiffness": lambda n: [(0.0, 300.0), (n, -1.0)],
}


@pytest.mark.parametrize("table", [*BAD_TABLES, "missing"])
def test_bad_tables_exit_2_with_one_line(tmp_path, capsys, table):
    length, _ = path_mm()
    config = write_table_config(tmp_path, BAD_TABLES.get(table, BAD_TABLES["short"])(length))
    if table == "missing":
        (config.parent / "pair.csv").unlink()
    status, stdout, err = run(capsys, config, "--out", tmp_path / "o")
    assert status == 2 and stdout == "" and not (tmp_path / "o").exists()
    assert err.count("\n") == 1 and err.startswith("hbgear: error: mesh.pair_stiffness_file = ") and "pair.csv" in err


@pytest.mark.parametrize(
    "argv, key",
    [
        (["--set", "profile.pinion_tip_relief_length_mm=14.0"], "profile.pinion_tip_relief_length_mm"),
        (["--set", "profile.gear_tip_relief_um=-2.0"], "profile.gear_tip_relief_um"),
        (["--set", "profile.shape=cubic"], "profile.shape"),
        (["--set", "mesh.k_max_MN_per_m=720.0"], "mesh.k_max_MN_per_m"),
        (["--set", "mesh.poisson_ratio=0.3"], "mesh.poisson_ratio"),
        (["--set", "gear.profile_shift_pinion=0.2"], "gear.contact_ratio"),
        (["--torque", "150", "--torque", "150"], "--torque"),
        (["--torque", "-5"], "--torque"),
    ],
)
def test_bad_input_exits_2_with_one_line(tmp_path, capsys, argv, key):
    status, stdout, err = run(capsys, ISO_EXAMPLE, "--out", tmp_path / "o", *argv)
    assert status == 2 and stdout == "" and not (tmp_path / "o").exists()
    assert err.count("\n") == 1 and err.startswith("hbgear: error: ") and key in err and "Traceback" not in err


def test_relief_with_the_rectangular_model_exits_2(tmp_path, capsys):
    status, _, err = run(capsys, PAPER, "--out", tmp_path / "o", "--set", "profile.gear_tip_relief_um=5.0",
                         "--set", "profile.gear_tip_relief_length_mm=3.0")
    assert status == 2 and err.startswith("hbgear: error: profile.gear_tip_relief_um = 5.0") and "'rectangular'" in err


@pytest.mark.parametrize("command", ["solve", "frc", "simulate", "stability-map"])
@pytest.mark.parametrize("setting, key", [
    ("profile.gear_tip_relief_length_mm=50.0", "profile.gear_tip_relief_length_mm"),  # longer than the path
    ("mesh.damping_model='constant'", "mesh.damping_model"),  # per pair: c k_j / k_mean only
    ("friction.model='LTI'", "friction.model"),  # LTI's c dD/dt with a varying D(s): not wired
])
def test_dynamic_commands_refuse_bad_tooth_contact_in_one_line(tmp_path, capsys, command, setting, key):
    """The dynamic commands take the per-pair contact (MODEL.md section 9) and check it as static-te does."""
    argv = [command, str(ISO_EXAMPLE), "--set", setting, "--out", str(tmp_path / "o")]
    argv += {"solve": ["--speed", "3000"], "simulate": ["--speed", "3000"]}.get(command, [])
    status = cli.main(argv)
    captured = capsys.readouterr()
    assert status == 2 and captured.err.startswith(f"hbgear: error: {key}") and captured.err.count("\n") == 1
    assert "Traceback" not in captured.err and not (tmp_path / "o").exists()


def test_dynamic_commands_refuse_a_bad_pair_table(tmp_path, capsys):
    length, _ = path_mm()
    config = write_table_config(tmp_path, [(0.0, 300.0), (0.5 * length, -5.0), (length, 300.0)])
    status = cli.main(["frc", str(config), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert status == 2 and err.startswith("hbgear: error: ") and err.count("\n") == 1 and "Traceback" not in err


# ----------------------------------------------------------------------------- a light --help


def _imports_after(code: str) -> dict:
    script = f"import sys\n{code}\nprint({{m: m in sys.modules for m in ('jax', 'matplotlib')}})"
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert result.returncode == 0, result.stderr
    return ast.literal_eval(result.stdout.strip().splitlines()[-1])


HELP = "from hbgear.cli import main\ntry:\n    main(['static-te', '--help'])\nexcept SystemExit:\n    pass"


def test_help_and_bad_input_do_not_import_matplotlib():
    assert not _imports_after(HELP)["matplotlib"]
    bad = "from hbgear.cli import main\nmain(['static-te', 'missing.toml'])"
    assert not _imports_after(bad)["matplotlib"]
    result = subprocess.run([sys.executable, "-m", "hbgear", "static-te", "--help"], capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 0 and "--torque" in result.stdout


def test_help_does_not_import_jax():
    assert not _imports_after(HELP)["jax"]


MODULES = ["hbgear/cli/static_te.py", "hbgear/build.py", "hbgear/config.py",
           *sorted(str(p.relative_to(ROOT)) for p in (ROOT / "hbgear" / "gear" / "contact").glob("*.py"))]


@pytest.mark.parametrize("module", MODULES)
def test_command_modules_import_no_jax_or_matplotlib_directly_at_module_level(module):
    tree = ast.parse((ROOT / module).read_text())
    names = [alias.name for node in tree.body if isinstance(node, ast.Import) for alias in node.names]
    names += [node.module or "" for node in tree.body if isinstance(node, ast.ImportFrom)]
    assert not [n for n in names if n.split(".")[0] in ("jax", "matplotlib")], module
