"""SIGTERM stops a command the way Ctrl-C does: ``kill``, ``timeout`` and a cluster's preemption keep the run resumable.

Python turns Ctrl-C (SIGINT) into KeyboardInterrupt, which unwinds the command: open files are
closed, the atomic writes in progress remove their temporaries, and the command prints how to
resume. SIGTERM's default is to die on the spot; :func:`interrupt_on_sigterm` makes it raise the
same exception instead.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any


class Stopped:
    """Which signal stopped the command (None: none yet); :attr:`exit_status` is the shell's 128 + signal."""

    def __init__(self) -> None:
        self.signal: int | None = None

    @property
    def exit_status(self) -> int:
        return 128 + (self.signal or signal.SIGINT)


@contextmanager
def interrupt_on_sigterm(*, children: bool = False) -> Iterator[Stopped]:
    """Within the block, SIGTERM (and SIGINT) raise KeyboardInterrupt; the previous handlers come back after it.

    ``children``: pass a SIGTERM on (as SIGINT, which the benchmark's workers turn into
    KeyboardInterrupt) to this process's multiprocessing children, which a SIGTERM sent to the
    parent alone would leave running until their current run ends (a terminal's Ctrl-C reaches
    them already).
    """
    stopped = Stopped()

    def stop(signum: int, frame: Any) -> None:
        first = stopped.signal is None
        stopped.signal = signum
        if children and first and signum == signal.SIGTERM:
            for child in multiprocessing.active_children():
                if child.pid is not None:
                    try:
                        os.kill(child.pid, signal.SIGINT)
                    except ProcessLookupError:  # it ended meanwhile
                        pass
        raise KeyboardInterrupt

    try:
        previous = {signum: signal.signal(signum, stop) for signum in (signal.SIGTERM, signal.SIGINT)}
    except ValueError:  # not the main thread (a test calling main() from a thread): signals stay as they are
        yield stopped
        return
    try:
        yield stopped
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
