"""Modules a later stage will import, imported now on a background thread.

A warm run spends most of its continuation inside compiled programs, which release the
interpreter lock; a module imported meanwhile on a thread (``scipy.integrate`` for the
period-doubling search's variational equations: ~0.2 s; matplotlib for the figures: ~0.4 s) is
then ready when its stage starts. Python's import lock makes a stage that imports it earlier
wait for the thread, not import it twice; a failed import is left to that stage to report.
"""

from __future__ import annotations

import importlib
import sys
import threading

__all__ = ["import_in_background"]


def import_in_background(*modules: str) -> threading.Thread | None:
    """Import `modules` (those not imported yet) on a daemon thread; **returns** it, or ``None``
    when there is nothing to import."""
    missing = [name for name in modules if name not in sys.modules]
    if not missing:
        return None

    def run():
        for name in missing:
            try:
                importlib.import_module(name)
            except Exception:  # noqa: BLE001 -- the stage that needs it imports it again and reports
                return

    thread = threading.Thread(target=run, name="hbgear-prefetch", daemon=True)
    thread.start()
    return thread
