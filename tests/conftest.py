"""Test-session settings for the long-lived test process.

- Not the user's disk compilation cache (``HBGEAR_NO_CACHE``): the CLI, called in-process by
  some tests, would otherwise turn on :mod:`hbgear.runtime`'s cache and read and write
  ``~/.cache/hbgear/jax``; the tests of the cache itself run in subprocesses with their own
  settings (tests/test_runtime.py). Instead one throw-away cache for the run, made empty at its
  start and shared by the workers, every program kept (no minimum compile time): the test files
  compile many of the same programs (the reference pair's corrector, Hill's pencils, ...), and a
  file after the first loads them. Five heavy files, two workers, empty cache at the start,
  one run each: 193.8 s wall against 210.1 s without (2026-12-02).
- JAX's in-memory compiled programs dropped after each test module: after ~1500 tests in one
  process the suite crashed inside XLA (abort / segmentation fault in test_structured, with and
  without the disk cache; each module alone passes) while every earlier module's programs were
  still held. Each module compiles what it uses anyway.
- The longest test files first (:data:`LONGEST_FIRST`): with ``--dist loadfile`` a file goes whole
  to one worker, which is handed the next file when it runs out of tests; started last, a long file
  would run alone at the end while the other worker idles.
- XLA's CPU code generation at optimisation level 0 (:data:`TEST_XLA_FLAGS`, added to any
  ``XLA_FLAGS`` of the environment before JAX starts; workers and subprocesses inherit it): the
  suite's time is mostly compiling programs that then run a few times (the relieved ISO pair's
  residual and Jacobian at H = 32, 64, 128: 52 s against 31 s). The graph-level passes (fusion,
  simplification) are the same; only LLVM's optimisation of the generated code is left out. Whole
  suite, two workers, with the Newton's Jacobian at full steps and the 8-DOF TI test's shaft
  damping (the same day): 562-817 s in three runs, against 1007-1276 s without the three
  (2026-12-03). With them, XLA's LLVM IR emitters, as the ``hbgear`` command uses them
  (:func:`hbgear.runtime.fast_compilation`; the runtime's own flag is not added in-process).
  ``tests/test_optimization_level.py`` runs one command at the product's settings
  against the suite's. ``HBGEAR_TEST_XLA_OPTIMIZED=1`` runs the suite at XLA's optimisation level.
- Figures drawn in the test's process (``HBGEAR_FIGURE_PROCESS=0``): the figure helper of
  ``hbgear frc`` (:mod:`hbgear.outputs.drawing`) imports matplotlib and JAX in a process of its
  own, ~1.5 s of a core that the suite's second worker is using; ``tests/test_drawing.py`` tests
  the helper, and a command with it against one without.
"""

from __future__ import annotations

import os
import shutil
import sys
import tempfile

import pytest

os.environ.setdefault("HBGEAR_NO_CACHE", "1")
os.environ.setdefault("HBGEAR_FIGURE_PROCESS", "0")

#: The suite's XLA code-generation flags (module docstring).
TEST_XLA_FLAGS = ("--xla_backend_optimization_level=0 --xla_llvm_disable_expensive_passes=true "
                  "--xla_cpu_use_fusion_emitters=false")
if os.environ.get("HBGEAR_TEST_XLA_OPTIMIZED") != "1" and TEST_XLA_FLAGS not in os.environ.get("XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = f"{os.environ.get('XLA_FLAGS', '')} {TEST_XLA_FLAGS}".strip()

#: The run's compilation cache directory: made by the controlling process (or a run without
#: workers) and handed to the workers it starts through the environment.
_CACHE_ENV = "HBGEAR_TEST_RUN_JAX_CACHE"


def pytest_configure(config):
    directory = os.environ.get(_CACHE_ENV)
    if directory is None:  # the controlling process, or a run without workers
        directory = os.environ[_CACHE_ENV] = tempfile.mkdtemp(prefix="hbgear-test-jax-cache-")
        config._hbgear_made_cache = directory
    import jax

    jax.config.update("jax_compilation_cache_dir", directory)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)


def pytest_unconfigure(config):
    made = getattr(config, "_hbgear_made_cache", None)
    if made is not None:
        shutil.rmtree(made, ignore_errors=True)
        os.environ.pop(_CACHE_ENV, None)


#: Test files by their time in a two-worker run, longest first (the sums of their slowest tests,
#: 2026-12-03, XLA code generation at level 0); the files not named follow in their usual order.
#: The pytest options (pyproject.toml) keep this order: ``--no-loadscope-reorder`` (xdist would otherwise start the
#: files with the most tests first, which puts these, with few and long tests, at the end).
LONGEST_FIRST = (
    "test_condensed.py",
    "test_pair_contact_stability.py",
    "test_friction_contact.py",
    "test_structured.py",
    "test_pair_contact_checks.py",
    "test_pair_contact.py",
    "test_hb.py",
    "test_hill.py",
    "test_bearings.py",
    "test_events.py",
    "test_study.py",
    "test_pair_contact_static.py",
    "test_frc_period_doubling.py",
    "test_lti.py",
    "test_optimization_level.py",
    "test_continuation.py",
)


def pytest_collection_modifyitems(config, items):
    rank = {name: k for k, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))  # stable: a file's own order kept


@pytest.fixture(autouse=True, scope="module")
def _fresh_jax_caches():
    yield
    if "jax" in sys.modules:
        sys.modules["jax"].clear_caches()
