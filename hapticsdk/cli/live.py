"""Live-session commands: ``view`` (a scene on simulated devices, shown in the browser)."""

from __future__ import annotations

import argparse
from typing import Any


def register(sub: Any) -> None:
    """Add ``view`` to the ``hapticsdk`` command."""
    from .argtypes import bounded_int, nonneg_float, positive_float

    p = sub.add_parser("view", help="run a live session on a scene and show it in the browser (127.0.0.1)")
    p.add_argument("scene", metavar="SCENE", help="scene JSON file")
    p.add_argument("--port", type=bounded_int(0, 65535), default=0, help="port on 127.0.0.1 (0: one the OS picks)")
    p.add_argument("--seconds", type=nonneg_float, default=None,
                   help="stop after this many seconds (default: at Ctrl-C)")
    p.add_argument("--speed", type=positive_float, default=40.0, metavar="MM_S",
                   help="speed of the simulated finger walking over the objects (mm/s)")
    p.add_argument("--record", metavar="RUN.npz|RUN.h5", help="also record every tick to this file (.h5 needs hapticsdk[h5])")
    p.set_defaults(func=cmd_view)


def cmd_view(args: argparse.Namespace) -> int:
    """``view``: open a session with the live view, print its address, run until
    ``--seconds`` or Ctrl-C; returns the exit status."""
    import time

    from ..runtime.session import Session
    from ..scene import Scene
    from ..sim.finger import walk_over

    scene = Scene.load(args.scene)
    finger = walk_over(scene, press_depth_mm=1.5, speed_mm_s=args.speed)
    with Session(scene, trajectory=finger, record=args.record) as s:
        url = s.open_view(args.port)
        print(f"live view of {scene.name!r}: {url}  (simulated finger over {len(scene.objects)} objects, "
              f"{finger.duration_s:.1f} s; Ctrl-C stops)", flush=True)
        end = None if args.seconds is None else time.monotonic() + args.seconds
        try:
            while end is None or time.monotonic() < end:
                time.sleep(0.1)
                s.state()  # raises when the servo is gone
        except KeyboardInterrupt:
            pass
        st = s.state()
        frames = s.view.frames
        summary = s.close()
    print(f"{st.ticks} ticks, {st.missed_ticks} missed; {frames} view frames sent; stopped: "
          f"{', '.join(summary.get('stopped', []))}" + (f"; recorded {summary['record_path']}"
                                                           if summary.get("record_path") else ""))
    return 0
