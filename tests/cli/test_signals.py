"""A signal is never swallowed: handled inside a GC callback (where an exception is
printed and ignored, e.g. JAX's after a long compiled call), it is raised again 50 ms
later from SIGALRM, so the job still stops and unwinds (`cli._main._stop`)."""

from __future__ import annotations

import gc
import signal
import sys
import time

import pytest

from piecs_bayes.cli import _main


def test_a_gc_callback_frame_is_recognised_and_a_normal_one_is_not():
    seen = []

    def callback(phase, info):
        if phase == "start" and not seen:
            seen.append(_main._swallowed_at(sys._getframe()))

    gc.callbacks.append(callback)
    try:
        gc.collect()
    finally:
        gc.callbacks.remove(callback)
    assert seen == [True]
    assert not _main._swallowed_at(sys._getframe())


def test_a_stop_inside_a_gc_callback_is_raised_later_outside_it():
    def callback(phase, info):
        if phase == "start":
            _main._stop(_main.Terminated, sys._getframe())  # would be swallowed: deferred

    previous = signal.getsignal(signal.SIGALRM)
    gc.callbacks.append(callback)
    try:
        with pytest.raises(_main.Terminated):
            gc.collect()
            gc.callbacks.remove(callback)
            deadline = time.time() + 5
            while time.time() < deadline:
                time.sleep(0.01)
    finally:
        if callback in gc.callbacks:
            gc.callbacks.remove(callback)
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
