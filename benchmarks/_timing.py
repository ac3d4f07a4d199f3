"""CPU time of an object's method calls, accumulated by part (for a benchmark's split of a loop's cost)."""
from __future__ import annotations

import time


def time_calls(obj, name: str, acc: dict, key: str) -> None:
    """Replace ``obj.name`` by a wrapper that adds the CPU time (this process) of each call to ``acc[key]``."""
    fn = getattr(obj, name)

    def wrapper(*a, **k):
        t = time.process_time()
        try:
            return fn(*a, **k)
        finally:
            acc[key] += time.process_time() - t

    setattr(obj, name, wrapper)
