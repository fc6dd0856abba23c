"""RSS of a live Session at 1 kHz (servo process and application), sampled every 2 s.
usage: python bench/bench_live_memory.py SECONDS. The scripted finger walks over the three-object scene of
examples/live_session.py again and again (press, slide, release) for the whole run; the
application polls state() and events() every 5 ms and retargets a material every 10 s.
The heartbeat timeout is off (the parent-process check stays): on a loaded machine the
application can miss 250 ms, which would stop the servo and end the measurement."""
import sys, time, os
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "examples"))
import hapticsdk as hs
from hapticsdk.scene import Scene
from hapticsdk.sim.finger import walk_over
from live_session import SCENE

def rss(pid):
    d = {}
    for line in open(f"/proc/{pid}/status"):
        if line.startswith(("VmRSS", "VmHWM")):
            k, v = line.split(":")
            d[k] = int(v.split()[0]) / 1024
    return d

def main():
    secs = float(sys.argv[1])
    scene = Scene.from_dict(SCENE)
    one = walk_over(scene, press_depth_mm=1.5, speed_mm_s=40.0)
    tr = one
    while tr.duration_s < secs + 30:
        tr = tr.then(one, gap_s=0.1)
    with hs.Session(scene, trajectory=tr, heartbeat_timeout_s=None) as s:
        pid = s.servo_pid
        t0 = time.monotonic(); nxt = t0; k = 0; last_retarget = t0
        while time.monotonic() - t0 < secs:
            st = s.state(); list(s.events())
            if time.monotonic() - last_retarget > 10:
                s.set_material("rubber", {"hardness": 0.5 + 0.4 * (k % 2), "roughness": 0.7}); k += 1
                last_retarget = time.monotonic()
            if time.monotonic() >= nxt:
                a, b = rss(pid), rss(os.getpid())
                print(f"{time.monotonic() - t0:7.1f} s  ticks {st.ticks:8d}  servo RSS {a['VmRSS']:7.1f} MB "
                      f"(HWM {a['VmHWM']:.1f})  app RSS {b['VmRSS']:7.1f} MB", flush=True)
                nxt += 2.0
            time.sleep(0.005)
        rep = s.close()
    print("overruns", rep.get("overruns") if isinstance(rep, dict) else rep)


if __name__ == '__main__':
    main()