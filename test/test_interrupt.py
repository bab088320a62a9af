"""Ctrl-C as a stop request (prsm_health/interrupt.py), with real signals to this process."""

from __future__ import annotations

import os
import signal
import time

import pytest

from prsm_health.interrupt import stop_on_interrupt


def _ctrl_c() -> None:
    os.kill(os.getpid(), signal.SIGINT)
    time.sleep(0.05)  # the handler runs in the main thread at the next bytecode


def test_the_first_ctrl_c_asks_to_stop_and_a_second_interrupts() -> None:
    before = signal.getsignal(signal.SIGINT)
    with stop_on_interrupt() as stop:
        assert not stop.is_set()
        _ctrl_c()
        assert stop.is_set()
        with pytest.raises(KeyboardInterrupt):  # a user who will not wait
            _ctrl_c()
    assert signal.getsignal(signal.SIGINT) is before
