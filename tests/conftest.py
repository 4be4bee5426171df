"""Test-session settings: no disk compilation cache in the test process.

The CLI, called in-process by some tests, turns on the disk compilation cache of
:mod:`hbgear.runtime`. In the long-lived test process that cache once made the suite abort inside
JAX's cache reader (``Fatal Python error: Aborted`` in ``get_executable_and_time``, twice, in
test_structured after ~1500 tests; not reproduced in a short session), and it would read and write
the user's ``~/.cache/hbgear/jax``. So the test process compiles without it
(``HBGEAR_NO_CACHE``); the tests of the cache itself run in subprocesses with their own settings
(tests/test_runtime.py).
"""

from __future__ import annotations

import os

os.environ.setdefault("HBGEAR_NO_CACHE", "1")


import sys  # noqa: E402

import pytest  # noqa: E402


@pytest.fixture(autouse=True, scope="module")
def _fresh_jax_caches():
    """Drop JAX's in-memory compiled programs between test modules. After ~1500 tests in one
    process the suite crashed inside XLA (abort / segmentation fault in test_structured, with and
    without the disk cache; each module alone passes): the compiled programs of every earlier
    module were still held. Each module compiles what it uses anyway."""
    yield
    if "jax" in sys.modules:
        sys.modules["jax"].clear_caches()
