"""Modules imported ahead on a background thread (hbgear.engine.prefetch)."""

import sys

from hbgear.engine.prefetch import import_in_background


def test_a_module_is_imported_on_the_thread_and_a_missing_one_is_left_to_its_stage():
    name = "wave"  # a small standard module nothing here uses: imported afresh without side effects
    sys.modules.pop(name, None)
    thread = import_in_background(name, "hbgear_no_such_module_for_the_test")
    assert thread is not None and thread.daemon
    thread.join(timeout=60)
    assert not thread.is_alive() and name in sys.modules
    assert "hbgear_no_such_module_for_the_test" not in sys.modules
    assert import_in_background(name) is None  # nothing left to import
