"""Process-wide settings: ``import hbgear`` changes none; ``hbgear.runtime.configure()`` sets up the
one-thread XLA runtime (leaving no thread pinned to one CPU) and the disk compilation cache."""

import os
import subprocess
import sys
import textwrap

import pytest

MULTI_CPU = pytest.mark.skipif(not hasattr(os, "sched_getaffinity") or len(os.sched_getaffinity(0)) < 2,
                               reason="needs CPU affinity (Linux) and at least two CPUs")


def _run(code: str, **env) -> str:
    """`code` in a fresh interpreter with `env` over this one's, less the suite's cache settings
    (tests/conftest.py): the default cache is part of what is tested here."""
    base = {k: v for k, v in os.environ.items() if k not in ("HBGEAR_CACHE_DIR", "HBGEAR_NO_CACHE")}
    out = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], env=dict(base, **env),
                         capture_output=True, text=True, check=True)
    return out.stdout + out.stderr


def test_import_changes_no_process_setting(tmp_path):
    out = _run("""
        import os, sys
        mask = os.sched_getaffinity(0)
        import hbgear
        print("jax imported:", "jax" in sys.modules)
        model = hbgear.build_model(hbgear.load_config("examples/paper_table1.toml"))
        sol = hbgear.solve(model, speed_rpm=3000.0, harmonics=4, samples=64)
        import jax
        pinned = [t for t in os.listdir("/proc/self/task") if os.sched_getaffinity(int(t)) != mask]
        print("cache:", jax.config.jax_compilation_cache_dir, "pinned:", len(pinned), "mask kept:",
              os.sched_getaffinity(0) == mask, "x64:", jax.config.jax_enable_x64)
    """, XDG_CACHE_HOME=str(tmp_path))
    assert "jax imported: False" in out
    assert "cache: None pinned: 0 mask kept: True x64: True" in out
    assert not (tmp_path / "hbgear").exists()


@MULTI_CPU
@pytest.mark.parametrize("setting", ["1", "default"])
def test_configure_restores_cpu_affinity_and_enables_the_cache(setting, tmp_path):
    out = _run("""
        import os, hbgear
        done = hbgear.runtime.configure()
        import jax, jax.numpy as jnp
        jnp.ones(3).sum().block_until_ready()
        mask = os.sched_getaffinity(0)
        pinned = [t for t in os.listdir("/proc/self/task") if os.sched_getaffinity(int(t)) != mask]
        print(len(mask), len(pinned), done["single_thread"], jax.config.jax_compilation_cache_dir == done["cache_dir"])
    """, HBGEAR_RUNTIME_THREADS=setting, XDG_CACHE_HOME=str(tmp_path))
    cpus, pinned, single, cache = out.split()
    assert int(cpus) == len(os.sched_getaffinity(0)) and int(pinned) == 0
    assert single == ("True" if setting == "1" else "False") and cache == "True"
    assert (tmp_path / "hbgear" / "jax").is_dir()


def test_unknown_runtime_threads_setting_warns_and_uses_one_thread():
    out = _run("import hbgear; hbgear.runtime.configure(cache=False)", HBGEAR_RUNTIME_THREADS="4")
    assert "HBGEAR_RUNTIME_THREADS = '4': expected '1' or 'default'" in out


def test_no_cache_setting_leaves_the_cache_off(tmp_path):
    out = _run("import hbgear; print(hbgear.runtime.configure(threads=False))", HBGEAR_NO_CACHE="1",
               XDG_CACHE_HOME=str(tmp_path))
    assert "'cache_dir': None" in out and not (tmp_path / "hbgear").exists()


def test_keep_freed_memory_is_opt_in_and_can_be_declined():
    out = _run("""
        import hbgear
        print(hbgear.runtime.configure(threads=False, cache=False))
    """)
    assert "'keep_freed_memory': True" in out
    out = _run("import hbgear; print(hbgear.runtime.configure(threads=False, cache=False))", HBGEAR_MALLOC="default")
    assert "'keep_freed_memory': False" in out


@pytest.mark.parametrize("setting, expected", [("", "1"), ("default", "default")])
def test_configure_limits_blas_to_one_thread_unless_declined(setting, expected):
    """JAX's CPU LAPACK calls go to SciPy's OpenBLAS: after ``configure()`` every BLAS library of
    the process runs one thread, also inside a compiled LU; ``HBGEAR_BLAS_THREADS=default`` keeps
    the libraries' own thread counts."""
    out = _run("""
        import hbgear
        from threadpoolctl import threadpool_info
        import scipy.linalg
        before = sorted(i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas")
        done = hbgear.runtime.configure(cache=False)
        import jax.numpy as jnp
        jnp.linalg.solve(jnp.eye(400) * 2.0, jnp.ones(400)).block_until_ready()
        after = sorted(i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas")
        print(done["single_thread_blas"], before, after)
    """, HBGEAR_BLAS_THREADS=setting)
    done, rest = out.strip().splitlines()[-1].split(" ", 1)
    before, after = (eval(part) for part in rest.replace("] [", "]|[").split("|"))
    assert after, "no BLAS library found in the process"
    if expected == "1":
        assert done == "True" and set(after) == {1}
    else:
        assert done == "False" and after == before


def test_the_disk_cache_stays_off_with_a_jax_whose_cached_programs_are_wrong(monkeypatch, tmp_path):
    import jax

    from hbgear import runtime

    assert runtime._release("0.10.2") == (0, 10, 2) and runtime._release("0.6.2.dev20250601") == (0, 6, 2)
    monkeypatch.setattr(jax, "__version__", "0.5.3")
    monkeypatch.delenv("HBGEAR_NO_CACHE", raising=False)
    with pytest.warns(RuntimeWarning, match="jax 0.5.3: the disk compilation cache stays off"):
        assert runtime.enable_compilation_cache(tmp_path / "cache") is None
    assert not (tmp_path / "cache").exists()


def test_a_corrector_loaded_from_the_disk_cache_gives_the_compiled_ones_answer(tmp_path):
    """A second compiled continuation corrector of the same problem is loaded from the disk cache
    (a new trace, the same program): its plain run returns the first one's tangent, bit for bit.
    With jax 0.5.3 the loaded program skipped its while loop and returned zeros."""
    out = _run("""
        import numpy as np, jax.numpy as jnp, hbgear
        assert hbgear.runtime.configure(threads=False)["cache_dir"]
        import jax; jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
        from hbgear.engine.hb import HarmonicBalance
        from hbgear.engine.system import Duffing
        from hbgear.engine.continuation import _Compiled
        from hbgear.engine.continuation.compiled import _jit_corrector
        hb, duffing = HarmonicBalance(1, 3, 1, 16), Duffing(damping=0.02, stiffness=1.0, cubic=0.1, forcing=0.05)
        rj = lambda z, p: hb.residual_and_jacobians(jnp.asarray(z), p, duffing)
        r = lambda z, p: hb.residual(jnp.asarray(z), p, duffing)
        y = np.append(np.linspace(0.1, -0.2, hb.size), 0.9); row = np.eye(hb.size + 1)[-1]
        tangents = []
        for _ in range(2):
            corrector = _Compiled(_jit_corrector(rj, r, hb.size), chord=True, scale=1.0)
            tangents.append(corrector(y, row, row @ y, row, 0, np.inf).tangent)
        print("norms", *(float(np.linalg.norm(t)) for t in tangents))
        print("difference", float(np.abs(tangents[0] - tangents[1]).max()))
        """, HBGEAR_CACHE_DIR=str(tmp_path / "cache"))
    norms = [float(v) for v in out.split("norms")[1].split()[:2]]
    assert norms[0] == pytest.approx(1.0, abs=1e-12), out
    assert float(out.split("difference")[1].split()[0]) == 0.0, out
    assert any((tmp_path / "cache").iterdir()), "nothing was written to the disk cache"


def test_the_cli_says_in_one_line_that_the_cache_stays_off_with_an_old_jax(tmp_path):
    example = os.path.join(os.path.dirname(__file__), "..", "examples", "paper_table1.toml")
    out = _run(f"""
        import sys, jax
        jax.__version__ = "0.5.3"
        from hbgear.cli import main
        sys.exit(main(["solve", {example!r}, "--speed", "3000", "--set", "solver.harmonics=4",
                       "--set", "solver.time_samples=16", "--out", {str(tmp_path / "out")!r}]))
        """, HBGEAR_CACHE_DIR=str(tmp_path / "cache"))
    said = [line for line in out.splitlines() if "warning" in line]
    assert said == ["hbgear: warning: jax 0.5.3: the disk compilation cache stays off (programs loaded from it "
                    "can return wrong results before jax 0.6.2; upgrade jax)"], out
    assert "3000 rpm: DTE rms" in out and not (tmp_path / "cache").exists()


@pytest.mark.parametrize("env, expected", [({}, "True 1 [1]"), ({"HBGEAR_BLAS_THREADS": "default"}, "False None"),
                                           ({"OPENBLAS_NUM_THREADS": "2"}, "False 2")])
def test_the_command_loads_openblas_without_threads_unless_declined(env, expected):
    """``blas_without_threads()`` (the command's first step) sets ``OPENBLAS_NUM_THREADS=1`` before
    NumPy loads, so its OpenBLAS starts with one thread; declined with ``HBGEAR_BLAS_THREADS=default``,
    and a value the user set is kept."""
    base = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", "HBGEAR_BLAS_THREADS")}
    code = """
        import os
        from hbgear.runtime import blas_without_threads
        done = blas_without_threads()
        value = os.environ.get("OPENBLAS_NUM_THREADS")
        if done:
            import numpy
            from threadpoolctl import threadpool_info
            print(done, value, sorted({i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"}))
        else:
            print(done, value)
    """
    out = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], env=dict(base, **env),
                         capture_output=True, text=True, check=True)
    assert out.stdout.strip() == expected


@pytest.mark.parametrize("env, expected", [
    ({}, "True --xla_cpu_use_fusion_emitters=false"),
    ({"HBGEAR_XLA_EMITTERS": "default"}, "False "),
    ({"XLA_FLAGS": "--xla_cpu_use_fusion_emitters=true"}, "False --xla_cpu_use_fusion_emitters=true"),
    ({"JAX_USED_FIRST": "1"}, "False "),
])
def test_configure_asks_for_the_llvm_emitters_unless_declined_or_too_late(env, expected):
    """``configure()`` adds the emitters' flag to ``XLA_FLAGS`` before JAX's CPU client exists;
    it leaves a user's choice, ``HBGEAR_XLA_EMITTERS=default`` and a process that used JAX first alone."""
    base = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", "HBGEAR_XLA_EMITTERS")}
    code = """
        import os
        if os.environ.get("JAX_USED_FIRST"):
            import jax.numpy as jnp
            jnp.ones(2).block_until_ready()
        import hbgear
        done = hbgear.runtime.configure(cache=False, memory=False)
        print(done["fast_compilation"], os.environ.get("XLA_FLAGS", ""))
    """
    out = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], env=dict(base, **env),
                         capture_output=True, text=True, check=True)
    assert out.stdout.strip("\n") == expected
