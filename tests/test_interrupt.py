"""Ctrl-C deferred to check points (ssl_sim.interrupt), at the two places where Python's own handling of SIGINT
was measured to fail while ``ssl-rescue run`` started: inside ``exec`` of a string and inside a weakref callback.

Each case runs as ``python -m`` (as the flaky CLI test did; the exec case only misbehaves there) and sends itself
SIGINT at that exact point, so the failing moment is hit every time instead of by timing."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"

_CHILD = '''
import os, signal, sys, weakref

from ssl_sim.interrupt import check_interrupt, deferred_sigint

CTRL_C = "os.kill(os.getpid(), signal.SIGINT)\\nfor _ in range(100000): pass"  # the signal, then bytecode to run


class Obj:
    pass


def ctrl_c(ref):
    os.kill(os.getpid(), signal.SIGINT)
    for _ in range(100000):
        pass


def main(where):
    try:
        with deferred_sigint():
            if where == "exec":  # how dataclasses and namedtuples make their methods while a module imports
                exec(CTRL_C)
            else:  # a weakref callback, as importlib's module-lock callback
                obj = Obj()
                ref = weakref.ref(obj, ctrl_c)
                del obj
            print("still running", file=sys.stderr)
            check_interrupt()
            print("after the check", file=sys.stderr)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    return 0


sys.exit(main(sys.argv[1]))
'''


@pytest.mark.parametrize("where", ["exec", "weakref_callback"])
def test_ctrl_c_at_a_fragile_point_is_raised_at_the_next_check(tmp_path, where):
    (tmp_path / "ctrl_c_child.py").write_text(_CHILD)
    env = dict(os.environ, PYTHONPATH=str(SRC))
    p = subprocess.run([sys.executable, "-m", "ctrl_c_child", where], cwd=tmp_path, env=env, capture_output=True,
                       text=True, timeout=60, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    # Python's handler instead: exec -> "interrupted", then killed by SIGINT (-2); weakref -> ignored, exit 0.
    assert p.returncode == 130, p.stderr
    assert p.stderr.splitlines() == ["still running", "interrupted"]  # held until the check, raised there


def test_sigint_ignored_by_the_parent_stays_ignored(tmp_path):
    """A run started with SIGINT ignored (``nohup``, a background job of a script) is not made interruptible."""
    code = ("import os, signal, sys\n"
            "from ssl_sim.interrupt import check_interrupt, deferred_sigint\n"
            "with deferred_sigint():\n"
            "    assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN\n"
            "    os.kill(os.getpid(), signal.SIGINT)\n"
            "    check_interrupt()\n"
            "print('finished')\n")
    env = dict(os.environ, PYTHONPATH=str(SRC))
    p = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=60,
                       preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
    assert p.returncode == 0 and p.stdout.strip() == "finished", p.stderr
