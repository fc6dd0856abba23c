"""hapticsdk-warmth: example third-party plugin adding a warmth dimension.

Nothing here is imported by hapticsdk unless a scene names ``warmth`` (or the
``peltier-virtual`` actuator, or the ``warmth`` model).
"""

__version__ = "0.1.0"

#: range of the hapticsdk plugin API this distribution is written for
hapticsdk_api = ">=1.0,<2"
