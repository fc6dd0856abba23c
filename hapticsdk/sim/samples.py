"""The last samples of a simulated actuator's waveform, kept in memory.

:class:`SampleWindow` keeps the blocks a simulation writes (one per servo tick) and drops
the oldest once the newer ones hold ``keep`` samples, so a live session of any length
holds at most ``keep`` samples plus one block (flat memory: a simulated voice coil at
5 kHz that kept everything grew by ~0.17 MB/s of session, 0.6 GB an hour). Dropping is
O(1) per block (a deque), so the servo tick that writes does not slow down as the
window fills.
"""

from __future__ import annotations

from collections import deque

import numpy as np


class SampleWindow:
    """The newest samples written, at least ``keep`` of them once that many were
    written (``keep=None``: every sample)."""

    __slots__ = ("keep", "_blocks", "_kept", "total")

    def __init__(self, keep: int | None = None) -> None:
        if keep is not None and (isinstance(keep, bool) or int(keep) < 1):
            raise ValueError(f"keep must be a number of samples >= 1 or None, got {keep!r}")
        self.keep = None if keep is None else int(keep)
        self._blocks: deque[np.ndarray] = deque()
        self._kept = 0
        #: samples written since creation or :meth:`clear`
        self.total = 0

    def append(self, block: np.ndarray) -> None:
        """Keep ``block`` (1-D); drop the oldest blocks that the newer ones make surplus."""
        n = block.size
        if not n:
            return
        blocks = self._blocks
        blocks.append(block)
        self._kept += n
        self.total += n
        keep = self.keep
        if keep is not None:
            while len(blocks) > 1 and self._kept - blocks[0].size >= keep:
                self._kept -= blocks.popleft().size

    def __len__(self) -> int:
        return self._kept

    def samples(self) -> np.ndarray:
        """The kept samples, oldest first, as one new array (the window is kept as one
        block from then on)."""
        if not self._blocks:
            return np.zeros(0)
        if len(self._blocks) > 1:
            one = np.concatenate(self._blocks)
            self._blocks.clear()
            self._blocks.append(one)
        return self._blocks[0].copy()

    def clear(self) -> None:
        """Forget every sample."""
        self._blocks.clear()
        self._kept = 0
        self.total = 0
