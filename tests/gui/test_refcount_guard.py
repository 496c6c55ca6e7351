"""The refcount guard keeps None/True/False alive under PySide6's reference drops."""

from __future__ import annotations

import sys
import time
from typing import Any

from daq.gui import refcount_guard
from daq.gui.views import LiveViews


def test_guard_restores_none_refcount(qtbot: Any) -> None:
    views = LiveViews()  # installs the guard
    qtbot.addWidget(views)
    views.show()
    if not refcount_guard.needed():
        assert not refcount_guard.install()
        return
    assert refcount_guard.install()
    t0 = time.monotonic()
    while time.monotonic() - t0 < 0.5:  # an idle plot window: PySide6 drops None refs here
        qtbot.wait(5)
    refcount_guard.top_up()
    for obj in (None, True, False):
        assert sys.getrefcount(obj) >= refcount_guard._baseline[id(obj)] - 10
