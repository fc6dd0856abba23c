"""A live session: three objects of different materials, a scripted finger sliding
across them, one material retargeted while the finger touches it, the servo's events
printed as they come, and a figure of force and vibration over time with the object
boundaries marked (needs matplotlib).

    python examples/live_session.py live_session.png
    python examples/live_session.py live_session.png --view 30   # also open the live view
                                                                  # in the browser, 30 s more

The servo runs in its own process (``isolation="process"``); this script only asks for
state, gets events through callbacks (on the SDK's own thread) and never blocks it;
the servo records every tick to a file (``record=``), which the figure is drawn from. Everything runs on simulated devices (generated
data: no real device, finger or material was measured).

Reading the figure: the force panel draws every tick in grey and its 20 ms running mean
in black. This script does not measure the simulated Omni's damping, so the stiff-wall
controller credits none of it (docs/runtime.md, Passivity item 2): each wall is rendered
within the controller's energy bound, which covers the whole session; the first contacts
spend it, the controller logs a warning, and from then on the arm holds back the force
above its Colgate spring, which is 0 without a measured damping. What the finger feels
after that is the voice coil's share. Measure the simulated arm once, nobody holding it,
before running this (``hapticsdk calibrate damping --device omni-virtual --device-option
finger=none --save``), and the arm keeps a Colgate spring of about 0.5 N/mm at 1 kHz on
every contact (docs/runtime.md, Passivity item 7).
"""

import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

import hapticsdk as hs
from hapticsdk.scene import Scene
from hapticsdk.sim.finger import walk_over

SCENE = {
    "schema_version": 2,
    "name": "three-samples",
    "objects": [
        {"name": "sponge", "material": "S1",   # leather on sponge
         "geometry": {"shape": "box", "half_size_mm": [20, 10, 20]}, "pose": {"position_mm": [-55, -10, 0]}},
        {"name": "rubber", "material": "S12",  # fabric on rubber
         "geometry": {"shape": "box", "half_size_mm": [20, 10, 20]}, "pose": {"position_mm": [0, -10, 0]}},
        {"name": "eva", "material": "S7",      # fabric on EVA
         "geometry": {"shape": "sphere", "radius_mm": 25}, "pose": {"position_mm": [55, -25, 0]}},
    ],
    # keep every dimension of every object, so each one is felt as force and vibration
    "settings": {"importance": {"enabled": False}, "solver": {"seed": 0}},
}
RETARGET = ("rubber", {"hardness": 0.95, "roughness": 0.7})


def main() -> None:
    import argparse
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("png", nargs="?", default="live_session.png")
    ap.add_argument("--view", type=float, default=None, metavar="SECONDS",
                    help="serve the live view on 127.0.0.1 and keep the session open this long after the walk")
    args = ap.parse_args()
    out_png = Path(args.png)
    scene = Scene.from_dict(SCENE)
    finger = walk_over(scene, press_depth_mm=1.5, speed_mm_s=40.0)
    record = Path(tempfile.mkdtemp()) / "live_run.npz"
    retarget: list = []

    def show(e) -> None:  # runs on the SDK's event thread, never in the servo
        where = f" {e.object}" if e.object else ""
        detail = f" {e.actuator}.{e.field} sent {e.value:.3g} ({e.count} ticks)" if e.kind == "clamp" else (
            f"  ({e.value:g})" if e.value else "")
        print(f"  t={e.t:6.3f} s  {e.kind}{where}{detail}")
        if e.kind == "material_switched":
            switched.set()

    handled = threading.Event()   # the retarget handler has finished (its solve can be slow on a busy machine)
    switched = threading.Event()  # the servo's material_switched event has been printed

    def on_contact(e) -> None:
        if e.object == RETARGET[0] and not retarget:
            try:
                r = s.set_material(*RETARGET)
                retarget.append(r)
                feats = ", ".join(f"{k}={v:.3g}" for f in r.features.values() for k, v in f.items())
                ok = r.wait(0.1)
                print(f"  -> {RETARGET[0]} retargeted to {RETARGET[1]} during contact: {r.source} answer "
                      f"({feats}), error {r.error:.3g}; "
                      + (f"rendered from tick {r.tick} (t={r.t:.3f} s)" if ok else "not acknowledged within 0.1 s"))
            finally:
                handled.set()

    def on_any(e) -> None:
        show(e)
        if e.kind == "contact_enter":
            on_contact(e)

    with hs.Session(scene, trajectory=finger, record=record, view=args.view is not None) as s:
        print(f"servo running in process {s.servo_pid}; objects: {s.objects}")
        if s.view is not None:
            print(f"live view: {s.view.url}  (open it in a browser)")
        # one callback for every event: the first one registered also gets the events
        # published since the session started (a contact made while this script was still
        # setting up, on a busy machine), a second one only those after it was registered
        s.on_event("*", on_any)
        time.sleep(finger.duration_s + 0.3 + (args.view or 0.0))
        # the walk is over; on a busy machine the event thread may still be in the
        # handler: let it finish, and let the servo render the new material, before closing
        if handled.wait(30.0) and retarget:
            switched.wait(10.0)
        st = s.state()
        print(f"servo: {st.ticks} ticks, {st.overruns} overruns, {st.skipped_ticks} skipped, "
              f"{st.renderer_errors} renderer errors, {st.clamps} clamps, {st.material_switches} switches")
        names = s.object_ids
        summary = s.close()
    print("stopped:", ", ".join(summary["stopped"]))
    retarget_t = retarget[0].t if retarget and retarget[0].switch.done() else None
    log = np.load(record)  # every tick, streamed by the servo (hapticsdk replay reads it too)
    plot(log, names, retarget_t, out_png)
    print("saved", out_png, "(generated data)")


def plot(log, names, retarget_t, out_png: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from hapticsdk.fileio import atomic_writer

    t = log["t"]
    obj = log["object_id"]
    fig, (ax1, ax2) = plt.subplots(2, 1, sharex=True, figsize=(12, 6))
    f = log["force_n"]
    ax1.plot(t, f, color="0.65", lw=0.5, label="force along the normal, every tick (N)")
    # what a finger feels of the count-level cycle: its running mean over 20 ms (20 ticks)
    w = 20
    mean = np.convolve(f, np.ones(w) / w, mode="same")
    ax1.plot(t, mean, color="k", lw=1.2, label="force, 20 ms running mean (N)")
    ax1.set_ylabel("force (N)")
    # the piezo's amplitude in V on the left, the voice coil's (0..1) on its own axis
    ax2c = ax2.twinx()
    for role, color, ax, unit in (("vibration", "tab:blue", ax2, "V"), ("coil", "tab:orange", ax2c, "0..1")):
        key = f"{role}.amplitude"
        if key in log:
            ax.plot(t, log[key], color=color, lw=1.0, label=f"{role} amplitude ({unit})")
    ax2.set_ylabel("piezo amplitude (V)", color="tab:blue")
    ax2c.set_ylabel("voice-coil amplitude (0..1)", color="tab:orange")
    ax2c.set_ylim(0.0, 1.05)
    ax2.set_xlabel("servo time (s)")
    colors = ["tab:green", "tab:red", "tab:purple", "tab:brown"]
    # shade each stretch of contact with one object; contact that flickers at an edge
    # (gaps under 0.1 s with the same object on both sides) counts as one stretch
    change = np.flatnonzero(np.diff(obj) != 0) + 1
    starts = np.concatenate([[0], change])
    ends = np.concatenate([change, [obj.size]])
    spans: list[list] = []
    for a, b in zip(starts, ends):
        oid = int(obj[a])
        if oid < 0 or b - a < 2:
            continue
        if spans and spans[-1][0] == oid and t[a] - spans[-1][2] < 0.1:
            spans[-1][2] = t[b - 1]
        else:
            spans.append([oid, t[a], t[b - 1]])
    labelled = set()
    for oid, ta, tb in spans:
        name = names.get(oid, str(oid))
        for ax in (ax1, ax2):
            ax.axvspan(ta, tb, color=colors[oid % len(colors)], alpha=0.15,
                       label=name if (ax is ax1 and name not in labelled) else None)
        labelled.add(name)
        # above the panel: the force trace may fill it to the top
        ax1.text(0.5 * (ta + tb), 1.01, name, ha="center", va="bottom", fontsize=9,
                 transform=ax1.get_xaxis_transform())
    stiff = [sp for sp in spans if names.get(sp[0]) == "rubber"]
    if stiff:
        _, ta, tb = stiff[0]
        # beside the panel, under its legend: inside it the note would cover the trace
        ax1.text(1.07, 0.3, "grey band on the rubber: count-level\ncycle of a quantised stiff wall\n"
                 "(finger 3-4 encoder counts deep;\n0.13 N per count)", transform=ax1.transAxes,
                 ha="left", va="top", fontsize=8)
    if retarget_t is not None:
        for ax in (ax1, ax2):
            ax.axvline(retarget_t, color="k", ls="--", lw=1.0)
        ax2.annotate(f"{RETARGET[0]} retargeted", (retarget_t, 0.85), xycoords=ax2.get_xaxis_transform(),
                     fontsize=9, xytext=(5, 0), textcoords="offset points",
                     bbox={"boxstyle": "round,pad=0.2", "fc": "white", "ec": "none", "alpha": 0.8})
    ax1.legend(loc="upper left", bbox_to_anchor=(1.07, 1.0), fontsize=8)
    h2, l2 = ax2.get_legend_handles_labels()
    hc, lc = ax2c.get_legend_handles_labels()
    ax2.legend(h2 + hc, l2 + lc, loc="upper left", bbox_to_anchor=(1.07, 1.0), fontsize=8)
    ax1.set_title("live session on simulated devices: objects under the finger (shaded), generated data", pad=16)
    fig.tight_layout()
    with atomic_writer(out_png, "wb") as fh:
        fig.savefig(fh, format="png", dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    main()
