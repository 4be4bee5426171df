"""Test-session settings for the long-lived test process.

- No disk compilation cache (``HBGEAR_NO_CACHE``): the CLI, called in-process by some tests,
  would otherwise turn on :mod:`hbgear.runtime`'s cache and read and write the user's
  ``~/.cache/hbgear/jax``; the tests of the cache itself run in subprocesses with their own
  settings (tests/test_runtime.py).
- JAX's in-memory compiled programs dropped after each test module: after ~1500 tests in one
  process the suite crashed inside XLA (abort / segmentation fault in test_structured, with and
  without the disk cache; each module alone passes) while every earlier module's programs were
  still held. Each module compiles what it uses anyway.
- The longest test files first (:data:`LONGEST_FIRST`): with ``--dist loadfile`` a file goes whole
  to one worker, which is handed the next file when it runs out of tests; started last, a long file
  would run alone at the end while the other worker idles.
"""

from __future__ import annotations

import os
import sys

import pytest

os.environ.setdefault("HBGEAR_NO_CACHE", "1")


#: Test files by their time in a two-worker run, longest first (seconds of the slowest ones, on a
#: loaded two-core machine); the files not named follow in their usual order. The pytest options
#: (pyproject.toml) keep this order: ``--no-loadscope-reorder`` (xdist would otherwise start the
#: files with the most tests first, which puts these, with few and long tests, at the end).
LONGEST_FIRST = (
    "test_friction_contact.py",
    "test_pair_contact_stability.py",
    "test_structured.py",
    "test_hb.py",
    "test_pair_contact.py",
    "test_pair_contact_checks.py",
    "test_pair_contact_static.py",
    "test_condensed.py",
    "test_events.py",
    "test_bearings.py",
    "test_hill.py",
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
