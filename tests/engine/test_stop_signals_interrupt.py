"""``biafc``'s stop signals (:func:`daq.cli.stop_signals.stop_signals_interrupt`), found by a
second reader: two signals back to back (systemd's SIGTERM then SIGHUP at a log-out) raised twice,
the second inside the first's clean-up (a thread's join: "release unlocked lock", exit 1; or a
hang); a StopSignal landing in a weakref callback was printed and dropped, and the study ran on
with its output open; and ``biafc``'s main called off the main thread failed ("signal only works
in main thread")."""

from __future__ import annotations

import os
import signal
import sys
import threading
import time

import pytest

from daq.cli.stop_signals import StopSignal, raise_if_stopped, stop_signals_interrupt

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")


def _wait_for_signal() -> None:
    time.sleep(1.0)  # the handler runs here, at the next bytecode
    raise AssertionError("no signal arrived")


def test_only_the_first_stop_signal_raises() -> None:
    before = signal.getsignal(signal.SIGTERM)
    with stop_signals_interrupt():
        with pytest.raises(StopSignal) as info:
            os.kill(os.getpid(), signal.SIGTERM)
            _wait_for_signal()
        assert info.value.signum == signal.SIGTERM
        os.kill(os.getpid(), signal.SIGTERM)  # in the first one's clean-up: ignored
        time.sleep(0.05)
    assert signal.getsignal(signal.SIGTERM) is before  # put back


def test_a_swallowed_stop_signal_is_raised_again_at_the_next_safe_point() -> None:
    with stop_signals_interrupt():
        try:
            os.kill(os.getpid(), signal.SIGTERM)
            _wait_for_signal()
        except StopSignal:
            pass  # as Python does with an exception in a weakref callback
        with pytest.raises(StopSignal):
            raise_if_stopped()
    raise_if_stopped()  # outside the block: nothing pending


def test_a_swallowed_ctrl_c_is_raised_again_at_the_next_safe_point() -> None:
    """A terminal's Ctrl-C during a study landed in a weakref callback ("Exception ignored in
    ... KeyboardInterrupt"): the study ran to its end and exited 0 (once in a fresh-clone CI
    run). SIGINT is now remembered as the other stop signals are."""
    before = signal.getsignal(signal.SIGINT)
    with stop_signals_interrupt():
        try:
            os.kill(os.getpid(), signal.SIGINT)
            _wait_for_signal()
        except KeyboardInterrupt as exc:
            assert not isinstance(exc, StopSignal)  # Ctrl-C's own: exit 130, not 128 + n
        with pytest.raises(KeyboardInterrupt):
            raise_if_stopped()
    raise_if_stopped()  # outside the block: nothing pending
    assert signal.getsignal(signal.SIGINT) is before  # put back


def test_a_swallowed_stop_signal_prints_no_traceback(monkeypatch: pytest.MonkeyPatch) -> None:
    """Python prints an exception dropped in a weakref callback ("Exception ignored in ...
    Traceback ... KeyboardInterrupt") through sys.unraisablehook; a stop signal's is raised
    again at the next safe point, so its traceback was noise on the study's terminal (once in a
    fresh-clone CI run). Any other dropped exception still reaches the hook."""
    import weakref

    seen: list[BaseException | None] = []
    monkeypatch.setattr(sys, "unraisablehook", lambda u: seen.append(u.exc_value))

    class Thing:
        pass

    def interrupted(_: object) -> None:
        os.kill(os.getpid(), signal.SIGINT)  # lands here, in the callback
        time.sleep(1.0)

    def bad(_: object) -> None:
        raise ValueError("a real bug in a callback")

    with stop_signals_interrupt():
        thing = Thing()
        ref = weakref.ref(thing, interrupted)
        del thing  # the callback runs, its KeyboardInterrupt is dropped
        assert ref() is None
        with pytest.raises(KeyboardInterrupt):
            raise_if_stopped()
        other = Thing()
        ref2 = weakref.ref(other, bad)
        del other
        assert ref2() is None
    assert [type(e) for e in seen] == [ValueError], seen


def test_biafc_runs_off_the_main_thread() -> None:
    from daq.cli.biafc import main

    got: list[object] = []

    def call() -> None:
        try:
            got.append(main(["bands"]))
        except Exception as exc:  # "signal only works in main thread" before
            got.append(exc)

    t = threading.Thread(target=call)
    t.start()
    t.join(60)
    assert got == [0], got


def test_a_sighup_after_the_first_signal_still_leaves_the_terminal(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """SIGTERM then SIGHUP (the terminal closes as the command stops): the ignored second one
    returned before sending the output to the null device, and a line printed on the way out
    failed on the hung-up terminal (a traceback, exit 1)."""
    import daq.cli.stop_signals as ss

    left: list[bool] = []
    monkeypatch.setattr(ss, "leave_the_terminal", lambda: left.append(True))
    with stop_signals_interrupt():
        with pytest.raises(StopSignal):
            os.kill(os.getpid(), signal.SIGTERM)
            _wait_for_signal()
        os.kill(os.getpid(), signal.SIGHUP)  # ignored, but the terminal is gone
        time.sleep(0.05)
    assert left == [True]


def test_a_signal_long_after_a_swallowed_one_raises_again(monkeypatch: pytest.MonkeyPatch) -> None:
    """After a stop signal swallowed where it landed, every later SIGTERM was ignored: the
    command stopped only on Ctrl-C or SIGKILL."""
    import daq.cli.stop_signals as ss

    monkeypatch.setattr(ss, "REPEAT_AFTER_S", 0.2)
    with stop_signals_interrupt():
        try:
            os.kill(os.getpid(), signal.SIGTERM)
            _wait_for_signal()
        except StopSignal:
            pass  # swallowed
        time.sleep(0.3)
        with pytest.raises(StopSignal):
            os.kill(os.getpid(), signal.SIGTERM)
            _wait_for_signal()
