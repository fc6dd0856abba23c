"""The servo loop's log ring is in memory before the first tick: a tick that first touched
a page of it waited for the kernel (and, in a virtual machine, the host) to provide that
page: 4.7-7.6 ms at 4 kHz on a 24 MB ring, about once a second, where the period is
0.25 ms."""

from __future__ import annotations

import os
import sys

import pytest

from hapticsdk.runtime import ServoLoop
from hapticsdk.sim.probe import VirtualProbe


def _present(addr: int, nbytes: int) -> list[bool]:
    """Whether each page of ``[addr, addr + nbytes)`` is in memory (``/proc/self/pagemap``,
    bit 63 of each page's entry; readable without privileges, the frame numbers then read
    as 0)."""
    page = os.sysconf("SC_PAGE_SIZE")
    first, last = addr // page, (addr + nbytes - 1) // page
    with open("/proc/self/pagemap", "rb") as f:
        f.seek(first * 8)
        data = f.read((last - first + 1) * 8)
    return [bool(int.from_bytes(data[i:i + 8], "little") >> 63) for i in range(0, len(data), 8)]


@pytest.mark.skipif(not sys.platform.startswith("linux") or not os.path.exists("/proc/self/pagemap"),
                    reason="/proc/self/pagemap is Linux's")
def test_every_page_of_the_log_ring_is_in_memory_after_start():
    # 60 s at 1 ms: a 60 000-row ring of several MB, beyond malloc's mmap threshold, so
    # its pages are fresh from the kernel and absent until written
    loop = ServoLoop(VirtualProbe(), [], {}, period_s=1e-3, log_seconds=60.0)
    loop.start(60.0)
    try:
        log = loop._log
        assert log.nbytes > 1 << 20
        present = _present(log.ctypes.data, log.nbytes)
        assert all(present), f"{present.count(False)} of {len(present)} pages not in memory"
    finally:
        loop.finish()
