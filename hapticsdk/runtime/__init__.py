"""Servo runtime: the loop that runs renderers against devices, its clocks, the optional
real-time settings of the servo thread, its tick statistics, the stop-on-signal facility
and the live session.

Names are imported lazily (``hapticsdk.runtime.ServoLoop`` imports the loop, and with it
scipy, only when first used), so ``hapticsdk --help`` and the signal facility stay light.
"""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING, Any

_LAZY = {
    "MonotonicClock": "clock", "SimulatedClock": "clock", "RealtimeSettings": "clock",
    "apply_realtime": "clock", "thread_cpu_clock_cost_s": "clock",
    "EVENT_KEYS": "loop", "LoopReport": "loop", "ServoLoop": "loop",
    "jitter_stats": "stats", "preemption_stats": "stats", "tick_stats": "stats",
    "SafeStop": "signals", "safe_stop_on_signals": "signals",
}

__all__ = sorted(_LAZY)

if TYPE_CHECKING:
    from .clock import MonotonicClock, RealtimeSettings, SimulatedClock, apply_realtime, thread_cpu_clock_cost_s
    from .loop import EVENT_KEYS, LoopReport, ServoLoop
    from .signals import SafeStop, safe_stop_on_signals
    from .stats import jitter_stats, preemption_stats, tick_stats


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(import_module(f"{__name__}.{_LAZY[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
