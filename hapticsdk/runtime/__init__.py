"""Servo runtime: the loop that runs renderers against devices, its clocks, the optional
real-time settings of the servo thread and its tick statistics."""

from .clock import MonotonicClock, RealtimeSettings, SimulatedClock, apply_realtime, thread_cpu_clock_cost_s
from .loop import EVENT_KEYS, LoopReport, ServoLoop
from .signals import SafeStop, safe_stop_on_signals
from .stats import jitter_stats, preemption_stats, tick_stats

__all__ = ["MonotonicClock", "SimulatedClock", "RealtimeSettings", "apply_realtime", "thread_cpu_clock_cost_s",
           "EVENT_KEYS", "LoopReport", "ServoLoop", "jitter_stats", "preemption_stats", "tick_stats",
           "SafeStop", "safe_stop_on_signals"]
