"""hbgear.cli: the command framework, exit codes, one-line errors, no files on bad input."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from hbgear import cli
from hbgear.errors import ConfigError, ConvergenceError
from hbgear.outputs.io import write_json_atomic

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "paper_table1.toml"


@pytest.fixture
def registry(monkeypatch):
    """An empty command registry holding only what the test registers."""
    monkeypatch.setattr(cli, "COMMANDS", {})
    monkeypatch.setattr(cli, "_load_builtin_commands", lambda: None)
    return cli.COMMANDS


@pytest.fixture
def dummy(registry):
    """A `dummy` command with a --speed option; records what it was called with."""
    calls = []

    def add_arguments(parser):
        parser.add_argument(
            "--speed", type=cli.positive_float("--speed", "a positive speed in rpm"), default=1.0
        )
        parser.add_argument("--mode", default="ok")

    def run(config, args, out_dir):
        calls.append((config, args, out_dir))
        if args.mode == "diverge":
            raise ConvergenceError("Newton at 13400 rpm: residual 1e-3 after 50 iterations")
        if args.mode == "interrupt":
            raise KeyboardInterrupt
        if args.mode == "badinput":
            raise ConfigError("gear.contact_ratio", 2.1, "a contact ratio in (1, 2)")
        write_json_atomic(out_dir / "result.json", {"speed_rpm": args.speed})
        return 0

    def validate(config, args):
        if args.speed > 50000:
            raise ConfigError("--speed", args.speed, "a speed <= 50000 rpm")

    cli.register(cli.Command("dummy", "a test command", add_arguments, run, validate))
    return calls


def run_main(capsys, *argv):
    status = cli.main([str(a) for a in argv])
    captured = capsys.readouterr()
    return status, captured.out, captured.err


def write(tmp_path, text, name="c.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_success_writes_into_out(dummy, tmp_path, capsys):
    out = tmp_path / "out"
    status, _, err = run_main(
        capsys, "dummy", EXAMPLE, "--out", out, "--speed", "1500", "--set", "solver.harmonics=16"
    )
    assert status == 0 and err == ""
    assert (out / "result.json").is_file()
    config, args, out_dir = dummy[0]
    assert config.solver.harmonics == 16 and args.speed == 1500.0 and out_dir == out


def test_default_out_dir(dummy, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    status, _, _ = run_main(capsys, "dummy", EXAMPLE)
    assert status == 0 and (tmp_path / "hbgear-out" / "dummy" / "result.json").is_file()


PAPER = EXAMPLE.read_text()
BAD_CONFIGS = {
    "teeth 0": PAPER.replace("teeth_pinion = 25", "teeth_pinion = 0"),
    "negative stiffness": PAPER.replace("k_max_MN_per_m = 720.0", "k_max_MN_per_m = -720.0"),
    "contact ratio 2.5": PAPER.replace("contact_ratio = 1.433", "contact_ratio = 2.5"),
    "unknown friction law": PAPER.replace('law = "coulomb"', 'law = "stribeck"'),
    "harmonics 0": PAPER.replace("harmonics = 32", "harmonics = 0"),
    "syntax error": PAPER.replace("[mesh]", "[mesh"),
}


@pytest.mark.parametrize(
    "case", ["missing file", *BAD_CONFIGS, "nan override", "malformed override", "bad speed"]
)
def test_bad_input_exits_2_with_one_line_and_no_files(dummy, tmp_path, capsys, case):
    out = tmp_path / "out"
    extra = []
    if case == "missing file":
        config = tmp_path / "nope.toml"
    elif case in BAD_CONFIGS:
        config = write(tmp_path, BAD_CONFIGS[case])
        assert BAD_CONFIGS[case] != PAPER
    else:
        config = EXAMPLE
        extra = {
            "nan override": ["--set", "mesh.damping_ratio=nan"],
            "malformed override": ["--set", "harmonics=32"],
            "bad speed": ["--speed", "-5"],
        }[case]
    status, stdout, err = run_main(capsys, "dummy", config, "--out", out, *extra)
    assert status == 2
    assert err.count("\n") == 1 and err.startswith("hbgear: error: "), err
    assert "Traceback" not in err and stdout == ""
    assert not out.exists()
    assert dummy == []


def test_messages_name_key_value_and_allowed(dummy, tmp_path, capsys):
    config = write(tmp_path, BAD_CONFIGS["teeth 0"])
    _, _, err = run_main(capsys, "dummy", config, "--out", tmp_path / "o")
    assert err.strip() == "hbgear: error: gear.teeth_pinion = 0: an integer in [5, 10000]"
    _, _, err = run_main(
        capsys, "dummy", EXAMPLE, "--out", tmp_path / "o", "--set", "mesh.damping_ratio=nan"
    )
    assert "mesh.damping_ratio = nan" in err
    _, _, err = run_main(capsys, "dummy", tmp_path / "nope.toml", "--out", tmp_path / "o")
    assert "nope.toml" in err and "readable TOML" in err


@pytest.mark.parametrize("speed", ["-5", "0", "nan", "inf", "fast", "1e999"])
def test_positive_float_option(dummy, tmp_path, capsys, speed):
    status, _, err = run_main(capsys, "dummy", EXAMPLE, "--out", tmp_path / "o", "--speed", speed)
    assert status == 2 and err.count("\n") == 1 and "--speed" in err and "positive" in err


def test_validate_hook_runs_before_out_dir(dummy, tmp_path, capsys):
    out = tmp_path / "out"
    status, _, err = run_main(capsys, "dummy", EXAMPLE, "--out", out, "--speed", "60000")
    assert status == 2 and "--speed" in err and not out.exists()


def test_unwritable_out_is_bad_input(dummy, tmp_path, capsys):
    blocker = write(tmp_path, "x", name="file")
    status, _, err = run_main(capsys, "dummy", EXAMPLE, "--out", blocker / "sub")
    assert status == 2 and err.startswith("hbgear: error: --out")


def test_convergence_error_exits_1(dummy, tmp_path, capsys):
    out = tmp_path / "out"
    status, _, err = run_main(capsys, "dummy", EXAMPLE, "--out", out, "--mode", "diverge")
    assert status == 1
    assert err.startswith("hbgear: did not converge: Newton at 13400 rpm") and err.count("\n") == 1
    assert not out.exists()  # created by this run, empty: removed again


def test_config_error_from_run_exits_2(dummy, tmp_path, capsys):
    out = tmp_path / "o"
    status, _, err = run_main(capsys, "dummy", EXAMPLE, "--out", out, "--mode", "badinput")
    assert status == 2 and err.startswith("hbgear: error: gear.contact_ratio")


def test_keyboard_interrupt_exits_130(dummy, tmp_path, capsys):
    out = tmp_path / "o"
    status, _, err = run_main(capsys, "dummy", EXAMPLE, "--out", out, "--mode", "interrupt")
    assert status == 130 and err.count("\n") == 1 and "interrupted" in err


def test_help_version_and_usage_errors(dummy, capsys):
    status, out, _ = run_main(capsys, "--help")
    assert status == 0 and "dummy" in out and "a test command" in out
    status, out, _ = run_main(capsys, "dummy", "--help")
    assert status == 0 and "--set" in out and "--out" in out and "--speed" in out
    status, out, _ = run_main(capsys, "--version")
    assert status == 0 and out.startswith("hbgear ")
    status, _, err = run_main(capsys)
    assert status == 2 and "usage" in err
    status, _, err = run_main(capsys, "nosuchcommand", "x.toml")
    assert status == 2 and err.count("\n") == 1 and "nosuchcommand" in err
    status, _, err = run_main(capsys, "dummy")  # CONFIG missing
    assert status == 2 and err.count("\n") == 1 and "CONFIG" in err


def test_register_rejects_duplicates(registry):
    command = cli.Command("x", "help", None, lambda c, a, o: 0)
    assert cli.register(command) is command
    cli.register(command)  # the same object again is harmless
    with pytest.raises(ValueError):
        cli.register(cli.Command("x", "other", None, lambda c, a, o: 0))
    other = cli.register(cli.Command("x", "other", None, lambda c, a, o: 0), replace=True)
    assert registry["x"] is other


def test_python_dash_m_entry_point(tmp_path):
    def run(*args):
        return subprocess.run(
            [sys.executable, "-m", "hbgear", *args], capture_output=True, text=True, timeout=60
        )

    result = run("--help")
    assert result.returncode == 0 and "usage: hbgear" in result.stdout
    result = run("--version")
    assert result.returncode == 0 and "0.1.0" in result.stdout
    result = run()
    assert result.returncode == 2


def test_console_script_flushes_what_was_printed_and_keeps_the_status():
    """console_main ends the process with os._exit: buffered output (a pipe) must still arrive whole."""
    code = ("import sys, hbgear.cli as cli\n"
            "def fake(**how):\n"
            "    print('x' * 200000, end='')\n"
            "    print('END', file=sys.stderr, end='')\n"
            "    sys.stdout.write('END')\n"
            "    return 5\n"
            "cli.main = fake\n"
            "cli.console_main()\n"
            "print('not reached')\n")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert result.returncode == 5
    assert result.stdout == "x" * 200000 + "END" and result.stderr == "END"


@pytest.mark.parametrize("how", ["plain", "profiled", "asked"])
def test_console_script_ends_normally_under_a_profiler_or_when_asked(how):
    """Profilers and coverage write their reports at exit: under one (or with
    HBGEAR_FAST_EXIT=0) the atexit handlers run; otherwise the process ends at once."""
    code = ("import atexit, sys, hbgear.cli as cli\n"
            "atexit.register(lambda: print('atexit ran'))\n"
            "cli.main = lambda **how: 0\n"
            + ("sys.setprofile(lambda *a: None)\n" if how == "profiled" else "")
            + "cli.console_main()\n")
    env = dict(os.environ, HBGEAR_FAST_EXIT="0" if how == "asked" else "1")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, env=env)
    assert result.returncode == 0
    assert ("atexit ran" in result.stdout) == (how != "plain")


def test_the_command_imports_without_the_garbage_collector_and_computes_with_it(tmp_path):
    """console_main pauses Python's cyclic collector for the imports; the command runs with it
    on again and the imports frozen. main() called from Python leaves the collector alone."""
    code = ("import gc, sys, hbgear.cli as cli\n"
            "def probe(config, args, out_dir):\n"
            "    print('run:', gc.isenabled(), gc.get_freeze_count() > 0)\n"
            "    return 0\n"
            "cli.register(cli.Command(name='probe', help='', add_arguments=None, run=probe, dynamic_model=False))\n"
            "print('before:', gc.isenabled())\n"
            f"argv = ['probe', 'examples/paper_table1.toml', '--out', {str(tmp_path / 'out')!r}]\n"
            "if sys.argv[1:] == ['library']:\n"
            "    print('status:', cli.main(argv), gc.isenabled(), gc.get_freeze_count())\n"
            "else:\n"
            "    sys.argv = ['hbgear', *argv]\n"
            "    cli.console_main()\n")
    env = dict(os.environ, HBGEAR_NO_CACHE="1")
    own = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, env=env)
    assert own.returncode == 0, own.stderr
    assert own.stdout.split("\n")[:2] == ["before: True", "run: True True"]
    library = subprocess.run([sys.executable, "-c", code, "library"], capture_output=True, text=True, timeout=120,
                             env=env)
    assert library.returncode == 0, library.stderr
    assert library.stdout.split("\n")[:3] == ["before: True", "run: True False", "status: 0 True 0"]


# ----------------------------------------------------------------------------- hbgear validate as a gate


@pytest.fixture
def fake_compare(monkeypatch):
    """`hbgear validate` with HB vs TI replaced by rows of given differences (no computation):
    DTE p2p 0.2 % off at 5000 rpm, 0.01 % elsewhere; records the speeds asked for."""
    from hbgear.cli import validate

    seen = []

    def compare(config, model, speed_rpm):
        seen.append(speed_rpm)
        p2p = 2e-3 if speed_rpm == 5000.0 else 1e-4
        return [speed_rpm, 3.0, 3.0, 12.0, 12.0 / (1 + p2p), 0.0, p2p], None, None

    monkeypatch.setattr(validate, "compare", compare)
    monkeypatch.setattr(validate, "_plot", lambda results, path: path.write_bytes(b"figure"))
    return seen


@pytest.mark.parametrize("form", [["--speed", "3000", "--speed", "4000"], ["--speed", "3000", "4000"]],
                         ids=["repeated", "one-flag"])
def test_validate_speed_flags_add_up(fake_compare, tmp_path, capsys, form):
    status, _, err = run_main(capsys, "validate", EXAMPLE, "--out", tmp_path, *form)
    assert status == 0 and err == ""
    assert fake_compare == [3000.0, 4000.0]  # the last flag does not win
    assert len((tmp_path / "validation.csv").read_text().splitlines()) == 1 + 2


def test_validate_exits_3_naming_what_disagrees_and_still_writes(fake_compare, tmp_path, capsys):
    status, _, err = run_main(capsys, "validate", EXAMPLE, "--out", tmp_path, "--speed", "3000", "5000")
    assert status == 3
    assert err.count("\n") == 1 and err.startswith("hbgear: validation failed: 5000 rpm DTE p2p HB vs TI +0.2 %"), err
    assert "3000 rpm" not in err and "RMS" not in err and "tolerance 0.1 %" in err
    assert len((tmp_path / "validation.csv").read_text().splitlines()) == 1 + 2
    assert (tmp_path / "validation.png").read_bytes() == b"figure"
    # a wider tolerance accepts the same differences
    status, _, err = run_main(capsys, "validate", EXAMPLE, "--out", tmp_path, "--speed", "3000", "5000",
                              "--tolerance", "5e-3")
    assert status == 0 and err == ""


@pytest.mark.parametrize("value", ["0", "-1e-3", "nan", "wide"])
def test_validate_rejects_a_bad_tolerance(fake_compare, tmp_path, capsys, value):
    status, _, err = run_main(capsys, "validate", EXAMPLE, "--out", tmp_path / "o", "--tolerance", value)
    assert status == 2 and err.count("\n") == 1 and "--tolerance" in err
    assert fake_compare == [] and not (tmp_path / "o").exists()
