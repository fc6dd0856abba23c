"""The live view's page in a headless Chromium, driven over the DevTools protocol on a
pipe (--remote-debugging-pipe): shared by ``runtime/test_view.py`` (what the page shows) and
``bench/bench_live_view.py`` (how fast: the page's frame rate and a material switch's
delay, the issue's goals, which depend on how soon this machine runs the browser, the
servo and the view's server)."""

import base64
import json
import os
import subprocess
import time
from pathlib import Path

import hapticsdk as hs
from hapticsdk.sim.finger import Trajectory

SCENE = {"schema_version": 2, "name": "two-pads",
         "objects": [
             {"name": "left", "material": {"intensities": {"hardness": 0.2}},
              "geometry": {"shape": "box", "half_size_mm": [20, 10, 20]}, "pose": {"position_mm": [-30, -10, 0]}},
             {"name": "right", "material": "S7",
              "geometry": {"shape": "sphere", "radius_mm": 15}, "pose": {"position_mm": [30, -15, 0]}}],
         "devices": {"force": "probe-virtual"},
         "settings": {"solver": {"seed": 0}, "importance": {"enabled": False}}}
HOLD = Trajectory([(0.0, -30.0, 3.0), (0.3, -30.0, -1.0), (600.0, -30.0, -1.0)])

#: how long a step waits for what it then reports (s): a bound on a stuck run, not a
#: measurement, so generous for a busy machine
WAIT_S = 30.0


class DevTools:
    """The DevTools protocol over --remote-debugging-pipe: JSON messages ended by NUL,
    commands on the browser's fd 3, answers and events on its fd 4."""

    def __init__(self, exe, profile):
        to_r, self._to_w = os.pipe()
        self._from_r, from_w = os.pipe()

        def fds():  # the protocol pipe on fds 3 and 4 (kept: close_fds=False)
            os.dup2(to_r, 3)
            os.dup2(from_w, 4)

        self.proc = subprocess.Popen(
            [exe, "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
             "--disable-component-update", "--no-first-run", f"--user-data-dir={profile}",
             "--remote-debugging-pipe", "--window-size=1100,760", "about:blank"],
            close_fds=False, preexec_fn=fds, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        os.close(to_r)
        os.close(from_w)
        self._buf = b""
        self._id = 0
        self.session = None

    def call(self, method, params=None, timeout=30.0):
        self._id += 1
        msg = {"id": self._id, "method": method, "params": params or {}}
        if self.session and not method.startswith("Target."):
            msg["sessionId"] = self.session
        os.write(self._to_w, json.dumps(msg).encode() + b"\0")
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            while b"\0" in self._buf:
                raw, self._buf = self._buf.split(b"\0", 1)
                m = json.loads(raw)
                if m.get("id") == self._id:
                    if "error" in m:
                        raise AssertionError(f"{method}: {m['error']}")
                    return m["result"]
            chunk = os.read(self._from_r, 1 << 20)
            if not chunk:
                raise AssertionError("chromium closed the pipe")
            self._buf += chunk
        raise AssertionError(f"{method}: no answer in {timeout} s")

    def open(self, url):
        tid = self.call("Target.createTarget", {"url": url})["targetId"]
        self.session = self.call("Target.attachToTarget", {"targetId": tid, "flatten": True})["sessionId"]

    def js(self, expr):
        r = self.call("Runtime.evaluate", {"expression": expr, "returnByValue": True})
        return r["result"].get("value")

    def close(self):
        try:
            os.close(self._to_w)
        except OSError:
            pass
        try:
            self.proc.wait(5)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(5)
        os.close(self._from_r)


def _until(pred, timeout=30.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        v = pred()
        if v:
            return v
        time.sleep(0.02)
    return None


def run_page(exe: str, profile: Path, screenshot: Path) -> dict:
    """Open a session with its view on SCENE, load the page in Chromium ``exe`` and
    return what it showed: ``frames`` (after waiting for 10), ``frames_advanced``
    (more came after that), ``obj``, ``objects``, ``gen`` (the page's texts), ``rate``
    (frames a second over about a second, browser clock), ``switch_shown`` and
    ``delay_ms`` (a material switch: from the servo's publication of the first tick
    that rendered it, machine clock, to the page's frame that showed it, browser clock,
    the same wall clock), ``switch_text``, and the screenshot's bytes (``png``, also
    written to ``screenshot``). Each step waits up to WAIT_S for what it reports."""
    out: dict = {}
    with hs.Session(SCENE, trajectory=HOLD, view=True) as s:
        out["url"] = s.view.url
        dt = DevTools(exe, profile)
        try:
            dt.open(s.view.url)
            frames = lambda: int(dt.js("(document.body && +document.body.dataset.frames) || 0") or 0)  # noqa: E731
            out["frames"] = _until(lambda: frames() >= 10, WAIT_S) and frames()
            out["obj"] = _until(lambda: dt.js("(document.getElementById('obj') || {}).textContent") == "left",
                                WAIT_S) and "left"
            out["objects"] = dt.js("document.getElementById('objects').textContent")
            out["gen"] = dt.js("document.getElementById('gen').textContent")
            f0, t0 = frames(), dt.js("performance.now()")
            time.sleep(1.0)
            f1, t1 = frames(), dt.js("performance.now()")
            out["rate"] = (f1 - f0) / ((t1 - t0) / 1e3)
            out["frames_advanced"] = bool(_until(lambda: frames() > f0, WAIT_S))
            wall_minus_mono = time.time() - time.monotonic()
            r = s.set_material("left", {"hardness": 0.9}, refine=False)
            out["switch_rendered"] = r.wait(WAIT_S)
            shown = _until(lambda: dt.js("(document.querySelector('#switches li') || {dataset: {}}).dataset.shownAt"),
                           WAIT_S)
            out["switch_shown"] = bool(shown)
            out["delay_ms"] = float(shown) - (r.switch.monotonic + wall_minus_mono) * 1e3 if shown else None
            out["switch_text"] = dt.js("(document.querySelector('#switches li') || {}).textContent") or ""
            out["png"] = base64.b64decode(dt.call("Page.captureScreenshot", {"format": "png"})["data"])
            screenshot.write_bytes(out["png"])
        finally:
            dt.close()
    return out
