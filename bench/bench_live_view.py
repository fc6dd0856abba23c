"""The live view's speed in a headless Chromium: the issue's goals for the page (issue 27).

``python bench/bench_live_view.py [--repeat 5] [--json]``

Needs Debian ``chromium``. Each run opens a process-isolated ``Session`` with its view on
the two-pad scene of ``tests/view_page.py`` (simulated devices, the finger held
in the left pad), loads the page in a headless Chromium driven over the DevTools protocol,
and switches the left pad's material once (what ``tests/runtime/test_view.py`` checks
the page shows; this script times it).

What it measures, per run: (1) the page's frame rate, frames it showed over about one
second on the browser's clock (``performance.now()``); (2) a material switch's delay,
from the servo's publication of the first tick that rendered it (``time.monotonic()``,
put on the wall clock) to the page's frame that showed it (``Date.now()``, 1 ms steps;
the same wall clock). Printed: the worst and the median of ``--repeat`` runs, held to
the goals: 30 frames a second or more, a switch shown within 100 ms (one 20 ms frame
period plus the page's and the machine's delays), ``met`` or ``MISSED``.

What it does not measure: a browser with a GPU or a display (headless,
``--disable-gpu``), a page on another machine, a real device's servo. Other processes'
load is in every figure (the load average is printed); these figures were asserted in
the test once, which a busy machine can fail without anything being wrong.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

#: the issue's goals: frames a second (at least), switch delay (ms, at most)
GOAL_RATE = 30.0
GOAL_DELAY_MS = 100.0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    if not 1 <= a.repeat <= 1000:
        ap.error("--repeat 1..1000")
    exe = shutil.which("chromium") or shutil.which("chromium-browser")
    if exe is None:
        print("missing: chromium (Debian package chromium)", file=sys.stderr)
        return 2
    from view_page import run_page
    load0 = os.getloadavg()
    runs = []
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(a.repeat):
            p = run_page(exe, Path(tmp) / f"profile{i}", Path(tmp) / f"view{i}.png")
            runs.append({"rate": p["rate"], "delay_ms": p["delay_ms"], "switch_shown": p["switch_shown"]})
    rates = [r["rate"] for r in runs]
    delays = [r["delay_ms"] for r in runs if r["delay_ms"] is not None]
    out = {"runs": runs, "repeat": a.repeat, "clock": "browser: performance.now() (rate), Date.now() against "
           "time.monotonic() on the wall clock (delay)",
           "rate_worst": min(rates), "rate_median": statistics.median(rates),
           "delay_ms_worst": max(delays) if delays else None,
           "delay_ms_median": statistics.median(delays) if delays else None,
           "switches_not_shown": sum(not r["switch_shown"] for r in runs),
           "goals": {"rate_at_least": GOAL_RATE, "delay_ms_at_most": GOAL_DELAY_MS},
           "loadavg_start": load0, "loadavg_end": os.getloadavg(), "cpus": os.cpu_count()}
    out["goals_met"] = {"rate": out["rate_worst"] >= GOAL_RATE,
                        "delay": bool(delays) and not out["switches_not_shown"] and max(delays) <= GOAL_DELAY_MS}
    if a.json:
        print(json.dumps(out, indent=1))
        return 0
    met = {True: "met", False: "MISSED"}
    print(f"live view in headless Chromium, {a.repeat} runs; worst (median):")
    print(f"  frame rate {out['rate_worst']:.1f} ({out['rate_median']:.1f}) frames/s on the browser's clock: "
          f"goal >= {GOAL_RATE:g} {met[out['goals_met']['rate']]}")
    if delays:
        print(f"  material switch shown {out['delay_ms_worst']:.1f} ({out['delay_ms_median']:.1f}) ms after the servo "
              f"rendered it (wall clock): goal <= {GOAL_DELAY_MS:g} ms {met[out['goals_met']['delay']]}"
              + (f"; {out['switches_not_shown']} switches never shown" if out["switches_not_shown"] else ""))
    else:
        print("  no switch was shown: goal MISSED")
    la0, la1 = out["loadavg_start"], out["loadavg_end"]
    print(f"load average (1/5/15 min) at the start {la0[0]:.2f}/{la0[1]:.2f}/{la0[2]:.2f}, at the end "
          f"{la1[0]:.2f}/{la1[1]:.2f}/{la1[2]:.2f} on {out['cpus']} CPUs (other processes' load is in these figures)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
