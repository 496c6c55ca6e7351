"""The bench window (PySide6 + pyqtgraph): ``biafc gui`` / ``biafc-gui``.

It drives the same :class:`daq.engine.RunEngine` as ``run_protocol``; the engine runs on its own
thread and its events reach the window through :class:`daq.gui.adapter.EngineEventAdapter`
(a Qt signal, queued to the GUI thread). No instrument is touched from the GUI thread.
"""
