"""Servo runtime: the loop that runs renderers against devices, its clocks and its
tick statistics."""

from .clock import MonotonicClock, SimulatedClock
from .loop import EVENT_KEYS, LoopReport, ServoLoop
from .stats import jitter_stats, tick_stats

__all__ = ["MonotonicClock", "SimulatedClock", "EVENT_KEYS", "LoopReport", "ServoLoop", "jitter_stats", "tick_stats"]
