"""A live view of a session in the browser: ``Session(view=True)`` or ``hapticsdk view``.

A small HTTP server (the standard library's ``http.server``, bound to 127.0.0.1 only,
a port the OS picks unless one is given) in the application's process serves one page
and a stream of server-sent events: every :data:`FRAME_S` (20 ms, 50 frames a second,
above the 30 a second goal) a frame of the session's state, read with
:meth:`Session.state <hapticsdk.runtime.session.Session.state>` and the vibration slots
of the shared block: nothing is sent to the servo and the servo does nothing for the
view (it costs the application one ``state()`` per frame and client).

The page draws, from the x-y plane of the device frame (x right, y up, mm), the objects
(boxes, spheres, planes of the scene, the object in contact highlighted) and the probe;
it shows the object in contact and the material it was last given, the force and the
vibration amplitudes as traces over the last 5 s (one point per frame: a trace of the
frames, not of every tick; the recording has every tick), the kept and dropped
dimensions of each object's plan, and the servo's timing (tick compute time, largest,
missed ticks, overruns, state age). The page writes, for each material switch it sees,
the browser's time of the frame that showed it (``#switches``), which the tests use to
measure how fast a switch shows.

Everything shown is simulated unless the scene's devices are real; the page says so.
"""

from __future__ import annotations

import json
import math
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any

#: time between two frames sent to a page (s): 50 frames a second
FRAME_S = 0.02
#: how long a page's stream lasts at most (s); the page reconnects on its own
STREAM_MAX_S = 3600.0


def scene_summary(session: Any) -> dict[str, Any]:
    """The static part of the view: the objects (name, geometry, pose) and, per
    object, the kept and dropped dimensions of its material's plan."""
    plan = session.plan
    by_obj: dict[str, Any] = {}
    for m in plan.materials.values():
        for o in m.objects:
            by_obj[o] = {"material": m.name, "kept": list(m.dimensions),
                         "dropped": [{"dimension": d.dimension, "reason": d.reason} for d in m.dropped]}
    objects = []
    for o in session.scene.objects:
        shape = o.shape()
        objects.append({"name": o.name, "geometry": shape.geometry_dict(), "pose": shape.pose.to_dict(),
                        **by_obj.get(o.name, {})})
    sim = all(getattr(_cls(n), "simulated", False) for n in session.devices.values())
    return {"scene": session.scene.name, "objects": objects, "devices": dict(session.devices),
            "simulated": sim}


def _cls(name: str) -> Any:
    try:
        from ..plugins import registry
        return registry("actuator").load(name)
    except Exception:  # noqa: BLE001 - only for the "simulated" label
        return None


def frame(session: Any) -> dict[str, Any]:
    """One frame of the live part (state, materials, vibration, timing)."""
    st = session.state()
    mats = session.objects
    vib = session._vibration()  # noqa: SLF001 - the session's own slots
    return {"t": st.t, "p": st.position_mm, "f": st.force_n, "obj": st.object, "near": st.near,
            "pen": st.penetration_mm, "material": mats.get(st.object) if st.object else None,
            "materials": mats, "switches": st.material_switches, "switched_at": st.switched_at,
            "vib": vib, "tick_us": st.tick_us, "tick_max_us": st.tick_max_us, "ticks": st.ticks,
            "missed": st.missed_ticks, "overruns": st.overruns, "age_ms": st.age_s * 1e3, "paused": st.paused}


class _Handler(BaseHTTPRequestHandler):
    server: "_Server"

    def log_message(self, format: str, *args: Any) -> None:  # noqa: A002 - quiet
        pass

    def do_GET(self) -> None:  # noqa: N802 - http.server's name
        if self.path in ("/", "/index.html"):
            body = _PAGE.replace("__SCENE__", json.dumps(self.server.static)).encode()
            self.send_response(200)
            self.send_header("Content-Type", "text/html; charset=utf-8")
            self.send_header("Content-Length", str(len(body)))
            self.send_header("Cache-Control", "no-store")
            self.end_headers()
            self.wfile.write(body)
        elif self.path == "/stream":
            self.send_response(200)
            self.send_header("Content-Type", "text/event-stream")
            self.send_header("Cache-Control", "no-store")
            self.end_headers()
            self.server.clients += 1
            end = time.monotonic() + STREAM_MAX_S
            nxt = time.monotonic()
            try:
                while not self.server.stopping.is_set() and time.monotonic() < end:
                    try:
                        data = frame(self.server.session)
                    except Exception as exc:  # noqa: BLE001 - the servo is gone: say so, end
                        msg = json.dumps({"error": f"{type(exc).__name__}: {exc}"})
                        self.wfile.write(f"event: end\ndata: {msg}\n\n".encode())
                        return
                    self.wfile.write(b"data: " + _json(data).encode() + b"\n\n")
                    self.wfile.flush()
                    self.server.frames += 1
                    nxt += FRAME_S
                    delay = nxt - time.monotonic()
                    if delay > 0:
                        self.server.stopping.wait(delay)
                    else:
                        nxt = time.monotonic()
            except (BrokenPipeError, ConnectionResetError):
                return
            finally:
                self.server.clients -= 1
        else:
            self.send_error(404)


def _finite(o: Any) -> Any:
    """``o`` with every non-finite float as None (JSON has no NaN or infinity; a browser's
    ``JSON.parse`` refuses the whole frame over one), containers walked."""
    if isinstance(o, float):
        return o if math.isfinite(o) else None
    if isinstance(o, dict):
        return {k: _finite(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_finite(v) for v in o]
    return o


def _json(o: Any) -> str:
    """One frame as strict JSON (non-finite numbers as null; anything else unknown as
    its text)."""
    return json.dumps(_finite(o), default=str, allow_nan=False)


class _Server(ThreadingHTTPServer):
    daemon_threads = True
    allow_reuse_address = True
    # set by ViewServer (declared for type checkers)
    session: Any
    static: Any
    stopping: threading.Event
    clients: int
    frames: int


class ViewServer:
    """Serves the live view of ``session`` on ``http://127.0.0.1:<port>/`` (``port`` 0:
    one the OS picks) from a daemon thread of the application; :meth:`close` stops it
    (the session closes it with itself)."""

    def __init__(self, session: Any, port: int = 0) -> None:
        from ..argcheck import number
        port = int(number(port, "port", lo=0, hi=65535, integer=True))   # a TCP port
        self.httpd = _Server(("127.0.0.1", port), _Handler)
        self.httpd.session = session  # type: ignore[attr-defined]
        self.httpd.static = scene_summary(session)  # type: ignore[attr-defined]
        self.httpd.stopping = threading.Event()  # type: ignore[attr-defined]
        self.httpd.clients = 0  # type: ignore[attr-defined]
        self.httpd.frames = 0  # type: ignore[attr-defined]
        self.port = self.httpd.server_address[1]
        self.url = f"http://127.0.0.1:{self.port}/"
        self._thread = threading.Thread(target=self.httpd.serve_forever, kwargs={"poll_interval": 0.1},
                                        name="hapticsdk-view", daemon=True)
        self._thread.start()

    @property
    def frames(self) -> int:
        """Frames sent so far (all pages)."""
        return int(self.httpd.frames)  # type: ignore[attr-defined]

    def close(self) -> None:
        """Stop serving: end every page's stream and close the socket."""
        self.httpd.stopping.set()  # type: ignore[attr-defined]
        self.httpd.shutdown()
        self.httpd.server_close()
        self._thread.join(2.0)


_PAGE = r"""<!doctype html>
<html><head><meta charset="utf-8"><title>hapticsdk live view</title>
<style>
body{font:13px system-ui,sans-serif;margin:10px;background:#fafafa;color:#222}
#wrap{display:grid;grid-template-columns:420px 1fr;gap:12px}
canvas{background:#fff;border:1px solid #ccc}
table{border-collapse:collapse}td{padding:1px 6px}
.gen{color:#a40;font-weight:bold}.k{color:#666}
</style></head><body>
<h3>hapticsdk live view: <span id="scene"></span> <span id="gen" class="gen"></span></h3>
<div id="wrap">
<div><canvas id="top" width="420" height="320"></canvas>
<div>in contact: <b id="obj">none</b> &middot; material: <b id="material">-</b> &middot; penetration <span id="pen"></span> mm</div>
<div>probe (mm): <span id="probe"></span></div>
<h4>objects</h4><table id="objects"></table></div>
<div><canvas id="force" width="620" height="150"></canvas><br>
<canvas id="vib" width="620" height="150"></canvas>
<h4>servo</h4><div id="timing"></div>
<h4>material switches seen</h4><ol id="switches"></ol>
<div class="k" id="status">connecting...</div></div></div>
<script>
const S = __SCENE__;
const $ = id => document.getElementById(id);
$("scene").textContent = S.scene;
$("gen").textContent = S.simulated ? "(simulated devices: generated data)" : "";
const hist = []; const SPAN = 5.0; let lastSw = null;
function objRows(f) {
  const rows = S.objects.map(o => {
    const m = f && f.materials ? f.materials[o.name] : o.material;
    const dr = (o.dropped || []).map(d => d.dimension + " (" + d.reason + ")").join(", ") || "none";
    return "<tr><td><b>" + o.name + "</b></td><td class=mat data-obj='" + o.name + "'>" + m +
      "</td><td>kept: " + (o.kept || []).join(", ") + "</td><td>dropped: " + dr + "</td></tr>";
  });
  $("objects").innerHTML = rows.join("");
}
objRows(null);
function drawTop(f) {
  const c = $("top"), g = c.getContext("2d"); g.clearRect(0, 0, c.width, c.height);
  let xs = [], ys = [];
  for (const o of S.objects) { const p = o.pose.position_mm || [0, 0, 0]; const G = o.geometry;
    const r = G.radius_mm || (G.half_size_mm ? Math.max(G.half_size_mm[0], G.half_size_mm[1]) : 30);
    xs.push(p[0] - r, p[0] + r); ys.push(p[1] - r, p[1] + r); }
  if (f) { xs.push(f.p[0]); ys.push(f.p[1]); }
  const x0 = Math.min(...xs, -60) - 10, x1 = Math.max(...xs, 60) + 10, y0 = Math.min(...ys, -40) - 10, y1 = Math.max(...ys, 20) + 10;
  const s = Math.min(c.width / (x1 - x0), c.height / (y1 - y0));
  const X = x => (x - x0) * s, Y = y => c.height - (y - y0) * s;
  for (const o of S.objects) { const p = o.pose.position_mm || [0, 0, 0]; const G = o.geometry;
    g.fillStyle = f && f.obj === o.name ? "rgba(220,80,40,0.45)" : "rgba(60,120,200,0.25)";
    g.strokeStyle = "#446";
    if (G.shape === "sphere") { g.beginPath(); g.arc(X(p[0]), Y(p[1]), G.radius_mm * s, 0, 7); g.fill(); g.stroke(); }
    else if (G.shape === "box") { const h = G.half_size_mm;
      g.fillRect(X(p[0] - h[0]), Y(p[1] + h[1]), 2 * h[0] * s, 2 * h[1] * s); g.strokeRect(X(p[0] - h[0]), Y(p[1] + h[1]), 2 * h[0] * s, 2 * h[1] * s); }
    else { g.fillRect(0, Y(p[1]), c.width, c.height - Y(p[1])); }
    g.fillStyle = "#000"; g.fillText(o.name, X(p[0]) - 12, Y(p[1]) + 4); }
  if (f) { g.fillStyle = "#111"; g.beginPath(); g.arc(X(f.p[0]), Y(f.p[1]), 5, 0, 7); g.fill(); }
  g.fillStyle = "#666"; g.fillText("x-y plane of the device frame (mm)", 6, 12);
}
function trace(id, key, names, unit, color) {
  // one scale per series (the piezo's volts and the voice coil's 0..1 differ a hundredfold),
  // each series' name and top written in its colour
  const c = $(id), g = c.getContext("2d"); g.clearRect(0, 0, c.width, c.height);
  if (!hist.length) return; const t1 = hist[hist.length - 1].t, t0 = t1 - SPAN;
  const series = key(hist[0]).length; const lo = [], hi = [];
  for (let k = 0; k < series; k++) { lo.push(0); hi.push(1e-9); }
  for (const h of hist) key(h).forEach((v, k) => { if (v != null) { hi[k] = Math.max(hi[k], v); lo[k] = Math.min(lo[k], v); } });
  g.fillStyle = "#000"; g.fillText(unit, 6, 12); let x0 = 6 + g.measureText(unit + "  ").width;
  for (let k = 0; k < series; k++) { g.strokeStyle = color[k % color.length]; g.beginPath(); let first = true;
    for (const h of hist) { const v = key(h)[k]; if (v == null) continue;
      const x = (h.t - t0) / SPAN * c.width, y = c.height - 14 - (v - lo[k]) / (hi[k] - lo[k]) * (c.height - 28);
      if (first) { g.moveTo(x, y); first = false; } else g.lineTo(x, y); } g.stroke();
    const text = (names[k] || "") + " top " + hi[k].toFixed(2) + "   ";
    g.fillStyle = color[k % color.length]; g.fillText(text, x0, 12); x0 += g.measureText(text).width; }
}
const es = new EventSource("/stream");
es.onmessage = ev => {
  const f = JSON.parse(ev.data); const now = Date.now();
  hist.push(f); while (hist.length && hist[0].t < f.t - SPAN) hist.shift();
  $("obj").textContent = f.obj || "none"; $("material").textContent = f.material || "-";
  $("pen").textContent = f.pen.toFixed(3); $("probe").textContent = f.p.map(v => v.toFixed(2)).join(", ");
  if (lastSw === null || f.switches !== lastSw) {
    if (lastSw !== null) { const li = document.createElement("li");
      li.dataset.shownAt = String(now); li.dataset.count = String(f.switches);
      li.textContent = "switch " + f.switches + " at servo t=" + f.t.toFixed(3) + " s: " + JSON.stringify(f.materials);
      $("switches").appendChild(li); }
    lastSw = f.switches; objRows(f);
  }
  $("timing").textContent = "tick " + f.tick_us.toFixed(1) + " us (max " + f.tick_max_us.toFixed(1) + " us), " + f.ticks +
    " ticks, " + f.missed + " missed, " + f.overruns + " overruns, state age " + f.age_ms.toFixed(2) + " ms" + (f.paused ? ", PAUSED" : "");
  $("status").textContent = "frames: " + hist.length + " in the last " + SPAN + " s";
  document.body.dataset.frames = String((+document.body.dataset.frames || 0) + 1);
  drawTop(f);
  trace("force", h => [h.f], ["force"], "force along the normal (N):", ["#000"]);
  trace("vib", h => Object.values(h.vib).map(v => v[1]), Object.keys(f.vib),
        "vibration amplitude (each in its actuator's unit, own scale):", ["#1f77b4", "#ff7f0e", "#2ca02c"]);
};
es.addEventListener("end", ev => { $("status").textContent = "session ended: " + ev.data; es.close(); });
drawTop(null);
</script></body></html>
"""
