"""Import-time JAX set-up: the one-thread XLA runtime must leave no thread pinned to one CPU."""

import os
import subprocess
import sys
import textwrap

import pytest

CHECK = textwrap.dedent("""
    import os, hbgear, jax, jax.numpy as jnp
    jnp.ones(3).sum().block_until_ready()
    mask = os.sched_getaffinity(0)
    pinned = [t for t in os.listdir("/proc/self/task") if os.sched_getaffinity(int(t)) != mask]
    print(len(mask), len(pinned))
""")


@pytest.mark.skipif(not hasattr(os, "sched_getaffinity") or len(os.sched_getaffinity(0)) < 2,
                    reason="needs CPU affinity (Linux) and at least two CPUs")
@pytest.mark.parametrize("setting", ["1", "default"])
def test_import_restores_cpu_affinity(setting):
    env = dict(os.environ, HBGEAR_RUNTIME_THREADS=setting)
    out = subprocess.run([sys.executable, "-c", CHECK], env=env, capture_output=True, text=True, check=True)
    cpus, pinned = map(int, out.stdout.split())
    assert cpus == len(os.sched_getaffinity(0)) and pinned == 0


def test_unknown_runtime_threads_setting_warns_and_uses_one_thread():
    env = dict(os.environ, HBGEAR_RUNTIME_THREADS="4")
    out = subprocess.run([sys.executable, "-c", "import hbgear"], env=env, capture_output=True, text=True, check=True)
    assert "HBGEAR_RUNTIME_THREADS = '4': expected '1' or 'default'" in out.stderr
