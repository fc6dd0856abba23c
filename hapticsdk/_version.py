"""The SDK's version, in a module that imports nothing (any stage may read it)."""

__version__ = "0.2.0"
