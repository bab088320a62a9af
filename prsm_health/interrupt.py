"""Ctrl-C as a request to stop, for the commands that end with what they have done so far.

``simulate`` closes a complete, shorter bag and ``replay`` reports what it read: both end
their loop when :func:`stop_on_interrupt`'s event is set instead of being torn down by
KeyboardInterrupt in the middle of a write (a second Ctrl-C does tear them down, for a user
who will not wait: :func:`removed_on_abort` then removes the output they were writing, and
``prsm-health`` says so in one line), and exit with :data:`EXIT_INTERRUPTED`, as do
``play`` and ``monitor`` (whose ROS session turns SIGINT and SIGTERM into its stop event:
:func:`prsm_health.ros.runtime.ros_session`).
"""

from __future__ import annotations

import shutil
import signal
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from types import FrameType

#: Exit code of a command stopped by Ctrl-C (128 + SIGINT, as a shell reports it).
EXIT_INTERRUPTED = 130


@contextmanager
def stop_on_interrupt() -> Iterator[threading.Event]:
    """An event that the first SIGINT sets while the block runs; the previous handler is back
    from then on (a second Ctrl-C interrupts at once, as before the block) and after it."""
    stop = threading.Event()
    previous = signal.getsignal(signal.SIGINT)

    def request_stop(_signal: int, _frame: FrameType | None) -> None:
        stop.set()
        signal.signal(signal.SIGINT, previous)

    signal.signal(signal.SIGINT, request_stop)
    try:
        yield stop
    finally:
        signal.signal(signal.SIGINT, previous)


@contextmanager
def removed_on_abort(output: Path | None) -> Iterator[None]:
    """Remove ``output`` (a bag this run is writing, which did not exist before it) when a
    second Ctrl-C tears the run down, and let the KeyboardInterrupt go on: the bag would be
    incomplete (no metadata.yaml, a cut MCAP), look like a result, and block the rerun."""
    try:
        yield
    except KeyboardInterrupt:
        if output is not None and remove_output(output):
            print(f"removed the incomplete {output}", file=sys.stderr)
        raise


def remove_output(output: Path) -> bool:
    """Remove the bag (directory or file) ``output`` that this run wrote; False if there is
    none."""
    if not (output.exists() or output.is_symlink()):
        return False
    if output.is_dir() and not output.is_symlink():
        shutil.rmtree(output, ignore_errors=True)
    else:
        output.unlink(missing_ok=True)
    return True
