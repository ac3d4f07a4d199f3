"""Ctrl-C in ``ssl-rescue run`` and ``ssl-robot``: SIGINT is recorded, and raised as KeyboardInterrupt only at
check points; a second Ctrl-C before the next check point is raised at once (a call that blocks for good).

Python's own SIGINT handler raises KeyboardInterrupt in whatever Python code the main thread runs next. While a
run starts (importing rerun, building the scene) that code is often not ours, and three outcomes were measured
(tests/test_run_outputs.py, signals sent 0-400 ms after ``--out`` appeared and as the viewer connected):

* raised inside a weakref callback or ``__del__`` (importlib's module-lock callback while rerun imports), the
  interrupt is printed as "Exception ignored in ..." and dropped: the run went on to its end and exited 0;
* raised inside ``exec``/``eval`` of a string (how dataclasses and namedtuples get their methods while a module
  imports), CPython 3.11 marks it unhandled although ``main`` caught it, and ``python -m`` then ends by killing
  itself with SIGINT (status -2) after printing "interrupted" instead of exiting 130;
* raised inside ``RerunLogger.__init__`` just after it connected to a viewer, the logger was never returned to be
  closed by the run: its exit-time close then waited 9 s on a stalled viewer and printed a warning after
  "interrupted".

Under :func:`deferred_sigint` the handler only sets a flag, and :func:`check_interrupt` raises KeyboardInterrupt
in our own code: after the slow imports and the viewer probe, and at every simulated control tick and audio block
(at most 0.8 s of wall time apart, measured on the loaded 2-core machine). A Ctrl-C during an import is acted on
when the import is done (rerun: 0.6 s idle, 1.5-5 s under load). ``ssl-robot`` checks at every wait of its mission
clock (the motion primitives' control ticks) and between behaviour steps: a dropped Ctrl-C there would leave the
robot driving. A second Ctrl-C before the first is acted on raises at once, wherever the program is, as Python's
own handling would (a device read that never returns still lets the user out).
"""
from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["deferred_sigint", "check_interrupt"]

_pending = False  # set by the handler; a plain bool: the handler must not take a lock the main thread may hold


def _record(signum: int, frame) -> None:
    global _pending
    if _pending:   # the second press: the first is still waiting for a check point
        raise KeyboardInterrupt
    _pending = True


def check_interrupt() -> None:
    """Raise KeyboardInterrupt if Ctrl-C was pressed under :func:`deferred_sigint` (a no-op otherwise). Cheap:
    call it wherever stopping is safe. The request stays pending until the context ends, so an interrupt
    swallowed on the way up is raised again at the next check or at the end of the context."""
    if _pending:
        raise KeyboardInterrupt


@contextmanager
def deferred_sigint() -> Iterator[None]:
    """Within: SIGINT only records the request; :func:`check_interrupt` raises it, and leaving the context with a
    request still pending raises it there. Only in the main thread and only while SIGINT has Python's default
    handler (a SIGINT ignored by the parent, e.g. in a background job, stays ignored); else nothing changes."""
    global _pending
    if (threading.current_thread() is not threading.main_thread()
            or signal.getsignal(signal.SIGINT) is not signal.default_int_handler):
        yield
        return
    _pending = False
    signal.signal(signal.SIGINT, _record)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)
        pressed, _pending = _pending, False
    if pressed:  # pressed after the last check (an exception already on its way out is not replaced)
        raise KeyboardInterrupt
