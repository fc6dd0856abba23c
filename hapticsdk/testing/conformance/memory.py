"""The memory a plugin holds as it keeps working: the ``renderer`` and ``vectorised``
rules read it with the standard library's ``tracemalloc``."""

from __future__ import annotations

from typing import Callable, Sequence


def _traced_after(counts: Sequence[int], step: Callable[[int], object]) -> list[int]:
    """Run ``step(k)`` for k = 0, 1, ... and read the memory traced (bytes) once ``counts[i]``
    steps have run, for each i (``tracemalloc``, started and stopped here unless the process
    already traces)."""
    import tracemalloc
    own = not tracemalloc.is_tracing()
    if own:
        tracemalloc.start()
    try:
        held: list[int] = []
        k = 0
        for n in counts:
            while k < n:
                step(k)
                k += 1
            held.append(tracemalloc.get_traced_memory()[0])
        return held
    finally:
        if own:
            tracemalloc.stop()
