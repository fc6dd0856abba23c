"""Deprecated since 0.2: moved to :mod:`hapticsdk.perception.channels` (removed in 0.3)."""

from ._deprecation import moved_module

__getattr__ = moved_module(__name__, globals())
