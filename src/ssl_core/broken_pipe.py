"""A command-line program whose reader went away (``ssl-locate rec.wav --stream | head``) ends quietly.

Python ignores SIGPIPE, so a write to a closed pipe raises ``BrokenPipeError`` wherever the program happens to be
printing, and the interpreter's final flush of stdout raises it once more ("Exception ignored ..."). The wrapped
``main`` instead stops at the first such write and exits with 141 (128 + SIGPIPE, what a shell reports for a
program the signal ended), printing nothing. The program's own clean-up (``finally`` blocks: stopping a robot's
motors) still runs, which restoring SIGPIPE's default action would skip.
"""
from __future__ import annotations

import functools
import os
import sys
from typing import Callable

#: Exit status after the reader of stdout went away (128 + SIGPIPE).
EXIT_BROKEN_PIPE = 141


def quiet_on_broken_pipe(main: Callable[..., int]) -> Callable[..., int]:
    """``main`` that returns :data:`EXIT_BROKEN_PIPE` when stdout's reader went away, with nothing more printed."""

    @functools.wraps(main)
    def wrapper(*args, **kwargs) -> int:
        try:
            code = main(*args, **kwargs)
            sys.stdout.flush()  # what is still buffered fails here, not in the interpreter's last flush
            return code
        except BrokenPipeError:
            _discard_stdout()
            return EXIT_BROKEN_PIPE

    return wrapper


def _discard_stdout() -> None:
    """Point stdout at /dev/null, so that the interpreter's last flush of what is still buffered goes nowhere."""
    try:
        fd = sys.stdout.fileno()
    except (AttributeError, OSError, ValueError):  # not a real file (a test's capture): nothing to flush at exit
        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, fd)
    finally:
        os.close(devnull)
