"""hapticsdk: multi-modal haptic rendering from perceptual targets."""

__version__ = "0.1.0"
