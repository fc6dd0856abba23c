"""A tiny application for the session failure tests: opens a process-isolated session
on a one-object hardness scene, prints the servo's pid, then waits to be killed."""

import sys
import time

import hapticsdk as hs
from hapticsdk.sim.finger import Trajectory

SCENE = {"schema_version": 1, "name": "pad",
         "objects": [{"name": "pad", "material": {"intensities": {"hardness": 0.5}}}],
         "settings": {"solver": {"seed": 0}}}


def main() -> None:
    tr = Trajectory([(0.0, 0.0, 2.0), (0.3, 0.0, -1.5), (600.0, 0.0, -1.5)])
    with hs.Session(SCENE, trajectory=tr) as s:
        print(f"servo {s.servo_pid} shm {s._buf.name}", flush=True)
        try:
            while True:
                time.sleep(0.05)
        finally:  # Ctrl-C (KeyboardInterrupt) leaves the with block: close() runs
            summary = s.close()
            print("closed:", ", ".join(summary.get("stopped", [])), flush=True)


if __name__ == "__main__":
    main()
    sys.exit(0)
