"""Interchange with other haptic engines: MPEG-I haptics (ISO/IEC 23090-31) ``.hjif``.

- :mod:`~hapticsdk.interop.hjif_model`: data structures, strict parsing (JSON paths in
  errors, size and depth caps), writing;
- :mod:`~hapticsdk.interop.hjif_export`: solved materials (a render plan) -> ``.hjif``;
- :mod:`~hapticsdk.interop.hjif_import`: what a file holds, SDK exports read back exactly;
- :mod:`~hapticsdk.interop.hjif_synth`: sample-accurate synthesis of vibrotactile content;
- :mod:`~hapticsdk.interop.hjif_play`: playback on the SDK's vibration actuators.

See ``docs/interop.md``.
"""

from __future__ import annotations

from .hjif_model import HapticFile, parse_hjif, parse_hjif_text, read_hjif

__all__ = ["HapticFile", "read_hjif", "parse_hjif", "parse_hjif_text"]
