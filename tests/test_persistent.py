"""Traced programs kept on disk (hbgear.engine.persistent): a kept program gives the traced
function's results bit for bit, is found only by its own key, never holds what its key does not
cover, and a warm ``hbgear frc`` loads every program it would trace and writes the same files."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hbgear.engine import persistent

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture
def kept(tmp_path):
    """Programs kept in a fresh folder for the test; the module's state restored after it."""
    state, stats = dict(persistent._STATE), dict(persistent._STATS)
    programs = dict(persistent._PROGRAMS)
    persistent._PROGRAMS.clear()
    persistent.enable(tmp_path / "programs")
    yield tmp_path / "programs"
    persistent._STATE.clear()
    persistent._STATE.update(state)
    persistent._STATS.update(stats)
    persistent._PROGRAMS.clear()
    persistent._PROGRAMS.update(programs)


def _new_process():
    """What a new process sees: no program in memory (the files stay)."""
    persistent._PROGRAMS.clear()


def _counts():
    s = persistent.stats()
    return s["exported"], s["loaded"], s["plain"]


def _fun(x, pair, scale=2.0):
    a, b = pair
    return {"sum": jnp.sin(x) * scale + a @ b, "n": jnp.sum(x > 0)}


def _equal(a, b):
    la, ta = jax.tree_util.tree_flatten(a)
    lb, tb = jax.tree_util.tree_flatten(b)
    return ta == tb and all(np.array_equal(np.asarray(u), np.asarray(v)) for u, v in zip(la, lb))


def test_a_kept_program_gives_the_traced_functions_results(kept):
    x, pair = np.linspace(-1, 1, 5), (np.arange(10.0).reshape(5, 2), np.ones(2))
    plain = jax.jit(_fun)(x, pair, 3.0)
    e0, l0, _ = _counts()
    first = persistent.persistent(jax.jit(_fun), "f", ("test", 1))(x, pair, 3.0)
    assert _counts()[:2] == (e0 + 1, l0)
    assert len(list(kept.rglob("f-*.bin"))) == 1
    _new_process()
    second = persistent.persistent(jax.jit(_fun), "f", ("test", 1))(x, pair, 3.0)
    assert _counts()[:2] == (e0 + 1, l0 + 1)
    assert _equal(first, plain) and _equal(second, plain)


def test_a_program_is_found_only_by_its_own_key(kept):
    x, pair = np.linspace(-1, 1, 5), (np.ones((5, 2)), np.ones(2))
    f = persistent.persistent(jax.jit(_fun), "f", ("test", 1))
    e0 = _counts()[0]
    f(x, pair, 3.0)
    f(x + 1.0, pair, 2.5)  # other values, same shapes and types: the same program
    assert _counts()[0] == e0 + 1
    f(x, pair, np.float64(3.0))  # a strongly typed scalar instead of a Python float
    f(np.linspace(-1, 1, 6), (np.ones((6, 2)), np.ones(2)), 3.0)  # other shapes
    persistent.persistent(jax.jit(_fun), "f", ("test", 2))(x, pair, 3.0)  # another closure
    assert _counts()[0] == e0 + 4
    assert len(list(kept.rglob("f-*.bin"))) == 4
    _new_process()
    # each reads its own file back: the results of the plain function for its own arguments
    g = persistent.persistent(jax.jit(_fun), "f", ("test", 1))
    assert _equal(g(x, pair, np.float64(3.0)), jax.jit(_fun)(x, pair, np.float64(3.0)))
    assert _equal(g(x - 2.0, pair, 0.5), jax.jit(_fun)(x - 2.0, pair, 0.5))


@jax.tree_util.register_dataclass
@dataclass(frozen=True)
class _Outside:
    """A node class outside hbgear: its source is not in the fingerprint."""
    gain: float
    law: str = field(default="x", metadata=dict(static=True))


def test_arguments_the_key_does_not_cover_are_never_kept(kept):
    def fun(x, node):
        return x * node.gain

    f = persistent.persistent(jax.jit(fun), "outside", ("test",))
    _, _, p0 = _counts()
    assert np.array_equal(f(np.ones(3), _Outside(2.0)), 2.0 * np.ones(3))
    assert _counts()[2] == p0 + 1 and not list(kept.rglob("outside-*"))
    g = persistent.persistent(jax.jit(lambda x, s: x), "string-leaf", ("test",))
    with pytest.raises(TypeError):  # a leaf that is not an array: the plain function's own error
        g(np.ones(2), object())
    assert not list(kept.rglob("string-leaf-*"))


def test_a_damaged_file_is_exported_again(kept):
    x, pair = np.linspace(0, 1, 4), (np.ones((4, 3)), np.ones(3))
    persistent.persistent(jax.jit(_fun), "f", ("test",))(x, pair)
    (path,) = kept.rglob("f-*.bin")
    path.write_bytes(b"not a program")
    _new_process()
    e0 = _counts()[0]
    again = persistent.persistent(jax.jit(_fun), "f", ("test",))(x, pair)
    assert _counts()[0] == e0 + 1 and _equal(again, jax.jit(_fun)(x, pair))
    assert path.read_bytes() != b"not a program"


def test_for_arguments_binds_one_program_and_checks_the_arguments(kept):
    f = persistent.persistent(jax.jit(lambda x, y: x * y), "bound", ("test",))
    bound = f.for_arguments(np.ones(3), 2.0)
    assert np.array_equal(bound(np.arange(3.0), 4.0), np.arange(3.0) * 4.0)
    with pytest.raises(Exception):  # noqa: B017 -- other shapes: the exported program refuses them
        bound(np.ones(4), 4.0)
    persistent.disable()
    assert np.array_equal(f.for_arguments(np.ones(3), 2.0)(np.ones(3), 3.0), 3.0 * np.ones(3))


def test_the_code_fingerprint_follows_every_source_file(tmp_path):
    (tmp_path / "pkg" / "sub").mkdir(parents=True)
    (tmp_path / "pkg" / "a.py").write_text("A = 1\n")
    (tmp_path / "pkg" / "sub" / "b.py").write_text("B = 2\n")
    before = persistent.code_fingerprint(tmp_path / "pkg")
    assert persistent.code_fingerprint(tmp_path / "pkg") == before
    (tmp_path / "pkg" / "sub" / "b.py").write_text("B = 3\n")
    changed = persistent.code_fingerprint(tmp_path / "pkg")
    (tmp_path / "pkg" / "sub" / "b.py").write_text("B = 2\n")
    (tmp_path / "pkg" / "sub" / "c.py").write_text("")
    added = persistent.code_fingerprint(tmp_path / "pkg")
    assert len({before, changed, added}) == 3


def test_programs_of_old_code_versions_are_removed_but_the_last_few(kept):
    for k in range(6):
        old = kept / f"{k:016x}"
        old.mkdir(parents=True)
        (old / "advance-x.bin").write_bytes(b"")
        os.utime(old, (1e9 + k, 1e9 + k))
    persistent._STATE["pruned"] = False
    persistent.persistent(jax.jit(_fun), "f", ("test",))(np.ones(2), (np.ones((2, 2)), np.ones(2)))
    left = sorted(d.name for d in kept.iterdir())
    assert len(left) == persistent.KEEP_OTHER_VERSIONS + 1
    assert [f"{k:016x}" for k in (3, 4, 5)] == [d for d in left if d.startswith("0000")]


def _frc(out: Path, cache: Path | None) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("HBGEAR_CACHE_DIR", "HBGEAR_NO_CACHE")}
    env.update({"HBGEAR_CACHE_DIR": str(cache)} if cache is not None else {"HBGEAR_NO_CACHE": "1"})
    subprocess.run([sys.executable, "-m", "hbgear", "frc", str(ROOT / "examples" / "paper_table1.toml"),
                    "--set", "friction.model=NLTV", "--set", "friction.law=arctan", "--set", "solver.harmonics=8",
                    "--set", "sweep.speed_rpm_start=3000", "--set", "sweep.speed_rpm_stop=3600",
                    "--out", str(out), "--no-progress"], env=env, cwd=ROOT, check=True, capture_output=True)
    return json.loads((out / "frc.json").read_text())


def test_a_warm_frc_run_loads_its_programs_and_writes_the_same_files(tmp_path):
    """The corrector and the variational equations' integration (the stability of every point) of
    an NLTV curve: exported by the first run, loaded by the second (nothing traced); both write
    the files of a run that keeps nothing."""
    cache = tmp_path / "cache"
    first = _frc(tmp_path / "first", cache)["programs"]
    second = _frc(tmp_path / "second", cache)["programs"]
    plain = _frc(tmp_path / "plain", None)["programs"]
    assert first["exported"] >= 2 and first["loaded"] == 0 and first["plain"] == 0, first
    assert second["exported"] == 0 and second["loaded"] == first["exported"], second
    assert plain["directory"] is None and plain["exported"] == plain["loaded"] == 0
    names = {p.name.split("-")[0] for p in (cache / "hbgear-programs").rglob("*.bin")}
    assert {"advance", "variational"} <= names, names
    for name in ("frc.csv", "floquet.csv", "orders.csv"):
        text = (tmp_path / "plain" / name).read_bytes()
        assert (tmp_path / "first" / name).read_bytes() == text
        assert (tmp_path / "second" / name).read_bytes() == text


def test_static_settings_are_in_the_key_and_traces_inside_other_functions_are_left_alone(kept):
    from hbgear.engine.hb import HarmonicBalance
    from hbgear.engine.system import Duffing
    from hbgear.engine.typed_jit import typed_jit

    f = persistent.persistent(typed_jit(lambda hb, x: x * hb.harmonics + hb.nu, static_argnums=0), "static",
                              ("test",), static_argnums=0)
    a, b = HarmonicBalance(1, 3), HarmonicBalance(1, 5)
    e0 = _counts()[0]
    assert np.array_equal(f(a, np.ones(2)), 4.0 * np.ones(2))
    assert np.array_equal(f(b, np.ones(2)), 6.0 * np.ones(2))
    assert _counts()[0] == e0 + 2  # one program per setting
    _new_process()
    g = persistent.persistent(typed_jit(lambda hb, x: x * hb.harmonics + hb.nu, static_argnums=0), "static",
                              ("test",), static_argnums=0)
    assert np.array_equal(g(b, np.ones(2)), 6.0 * np.ones(2)) and np.array_equal(g(a, np.ones(2)), 4.0 * np.ones(2))

    @dataclass(frozen=True)
    class Settings:  # frozen but not hbgear's: its repr need not say all of it
        harmonics: int = 2
        nu: int = 1

    _, _, p0 = _counts()
    assert np.array_equal(f(Settings(), np.ones(2)), 3.0 * np.ones(2))
    assert _counts()[2] == p0 + 1
    # inside another function's trace: the plain function, nothing exported
    e1 = _counts()[0]
    assert np.array_equal(jax.jit(lambda x: f(a, x))(np.ones(3)), 4.0 * np.ones(3))
    assert _counts()[0] == e1
    # the harmonic-balance residual of a system of hbgear's: kept, and the plain one's numbers
    hb, duffing = HarmonicBalance(1, 3, 1, 16), Duffing(damping=0.02, stiffness=1.0, cubic=0.1, forcing=0.05)
    z = np.linspace(0.1, -0.2, hb.size)
    kept_residual = np.asarray(hb.residual(z, 0.9, duffing))
    _new_process()
    loaded_residual = np.asarray(hb.residual(z, 0.9, duffing))
    persistent.disable()
    plain_residual = np.asarray(hb.residual(z, 0.9, duffing))
    assert np.array_equal(kept_residual, plain_residual) and np.array_equal(loaded_residual, plain_residual)
    assert list(kept.rglob("hb_residual_jit-*.bin"))


def test_static_fields_are_described_field_by_field_or_not_kept():
    """A static field holding frozen dataclasses of hbgear's (the relieved pair's mesh) is in the
    key field by field, so another relief is another program; anything else is not kept."""
    from hbgear.build import build_model
    from hbgear.config import load_config
    from hbgear.gear.system import GearSystem

    def relieved(tip_relief_um):
        config = load_config(ROOT / "examples" / "iso_tip_relief.toml",
                             [f"profile.pinion_tip_relief_um={tip_relief_um}"])
        return GearSystem(build_model(config))

    structure = {um: persistent._describe_structure(jax.tree_util.tree_structure(relieved(um))) for um in (24.0, 25.0)}
    assert structure[24.0] != structure[25.0]
    assert "hbgear.gear.contact.profile.FlankRelief" in repr(structure[24.0])

    @dataclass(frozen=True)
    class Outside:
        a: float = 1.0

    @dataclass
    class Mutable:
        a: float = 1.0

    for value in (Outside(), [np.ones(2)], {"a": 1}, np.ones(1)):
        with pytest.raises(persistent._NotCovered):
            persistent._describe(value)
    assert persistent._describe((1, 1.0, True)) != persistent._describe((1.0, 1, True))  # types count
    with pytest.raises(persistent._NotCovered):
        persistent._describe(Mutable())
