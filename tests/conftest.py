"""Test-session settings for the long-lived test process.

- No disk compilation cache (``HBGEAR_NO_CACHE``): the CLI, called in-process by some tests,
  would otherwise turn on :mod:`hbgear.runtime`'s cache and read and write the user's
  ``~/.cache/hbgear/jax``; the tests of the cache itself run in subprocesses with their own
  settings (tests/test_runtime.py).
- JAX's in-memory compiled programs dropped after each test module: after ~1500 tests in one
  process the suite crashed inside XLA (abort / segmentation fault in test_structured, with and
  without the disk cache; each module alone passes) while every earlier module's programs were
  still held. Each module compiles what it uses anyway.
"""

from __future__ import annotations

import os
import sys

import pytest

os.environ.setdefault("HBGEAR_NO_CACHE", "1")


@pytest.fixture(autouse=True, scope="module")
def _fresh_jax_caches():
    yield
    if "jax" in sys.modules:
        sys.modules["jax"].clear_caches()
