"""``voicecoil-audio`` measured through a JACK loopback, for as long as you like (the
issue's underrun goal: 10 minutes with a busy application thread).

``python bench/bench_voicecoil_audio.py [--minutes 10] [--period 128] [--rate 48000]
[--isolation process|thread] [--reference-seconds 60] [--hogs N] [--no-busy] [--json]``

Needs Debian ``jackd2`` and ``libportaudio2`` and ``pip install hapticsdk-hardness[audio]``.
It starts a private JACK server on its dummy driver (real-time scheduling when allowed),
opens the coil on it (``--isolation``: the backend's default, the stream in an audio
process of its own, unless told otherwise), and captures the output back through a
loopback port (:mod:`hapticsdk_hardness.audio_loopback`).

What it measures, on the same capture clock: (1) frequency error, amplitude error
against ``amplitude x full_scale``, command-to-sound and stop-to-silence times, over 8
runs at random frequencies (20..1000 Hz) and amplitudes (0.1..1; seeded) -- the worst of
each is printed, and the median of the two times; times through the loopback, and with
the output's reported latency added (``dac``). The clock is the capture stream's
(PortAudio's stream time on JACK's frame clock: ``jack_frame_time`` when the capture
callback runs); command-to-sound runs from just before the first command to the first
loud captured sample, stop-to-silence from just after ``stop()`` returns to the last
loud one. These two are the issue's latency goals, checked here and only here (the
tests check that the sound starts after the command and stops, not how soon: the
figures depend on how soon this machine runs the audio processes): command-to-sound
with the output latency within 10 ms (the servo command period, 1 ms, + one audio
period for the callback to pick the target up + one in the graph: 6.3 ms at 48 kHz and
128 frames, the rest for scheduling), stop-to-silence with the output latency within
20 ms (the block being rendered + one in the graph, the rest for scheduling); the worst
of the 8 runs is held to each goal; (2) underruns counted by the stream while a servo-like thread commands
the coil every 1 ms and (unless ``--no-busy``) another Python thread computes without
pause, for ``--minutes``: output underflows PortAudio flagged to the callback (in the
audio process, read from its shared counters) and the JACK server's own xrun count over
the same time; then, as references in the same run and the same conditions, the other
isolation for ``--reference-seconds`` (0: none) and JACK's C example client
(``jack_simple_client``) over 30 s, what this machine gives a client that needs no Python
interpreter lock. ``--hogs N`` adds N processes that spin on the CPU (at the default
priority) for the whole run, a loaded machine made on purpose. The load average is printed at the start and the end (other
processes' load is in these figures).

What it does not measure: a sound card's converters (the dummy driver has none), an
amplifier or the coil; the servo loop's own delay before its command (the commands come
from a plain loop here); and a machine other than this one at this moment: other
processes' load is in every figure (see the load average printed).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import random
import statistics
import subprocess
import sys
import threading
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from hapticsdk_hardness.audio import VoiceCoilAudio

#: the issue's latency goals (ms, with the output latency; see the module doc), for the
#: worst of the 8 runs
GOALS_MS = {"latency_dac_ms": 10.0, "stop_dac_ms": 20.0}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--period", type=int, default=128, help="JACK period (frames)")
    ap.add_argument("--rate", type=int, default=48000)
    ap.add_argument("--no-busy", action="store_true")
    ap.add_argument("--isolation", choices=("process", "thread"), default=None,
                    help="where the stream runs (default: the backend's default)")
    ap.add_argument("--reference-seconds", type=float, default=60.0,
                    help="the other isolation, same conditions, right after (0: skip)")
    ap.add_argument("--hogs", type=int, default=0, help="processes spinning on the CPU during the run")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    from hapticsdk.devices.safety import SafetyLayer
    from hapticsdk_hardness.audio import DEFAULT_ISOLATION, VoiceCoilAudio
    from hapticsdk_hardness.audio_loopback import JackServer
    why = JackServer.available()
    if why:
        print(f"missing: {why}", file=sys.stderr)
        return 2
    rng = random.Random(a.seed)
    iso = a.isolation or DEFAULT_ISOLATION
    other = "thread" if iso == "process" else "process"
    out: dict = {"rate": a.rate, "period": a.period, "minutes": a.minutes, "busy": not a.no_busy, "isolation": iso,
                 "cpus": os.cpu_count(), "loadavg_start": os.getloadavg()}

    def new_coil(isolation: str) -> VoiceCoilAudio:
        return VoiceCoilAudio(device="system", isolation=isolation,
                              safety=SafetyLayer(VoiceCoilAudio.limits, ramp_time_s=0.0))
    out["hogs"] = a.hogs
    hogs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(a.hogs)]
    try:
        return _run(a, out, iso, other, new_coil, rng, hogs)
    finally:
        for h in hogs:
            h.kill()
            h.wait()


def _run(a, out, iso, other, new_coil, rng, hogs) -> int:
    from hapticsdk_hardness.audio_loopback import JackServer, LoopbackCapture, hold, measure
    with JackServer(rate=a.rate, period=a.period) as srv:
        out["jack_realtime"] = "-R" in (srv.proc.args if srv.proc is not None else [])
        coil = new_coil(iso)
        with LoopbackCapture(srv) as cap, coil:
            cap.route()
            runs = [measure(coil, cap, frequency_hz=rng.uniform(20, 1000), amplitude=rng.uniform(0.1, 1.0),
                            seconds=0.5) for _ in range(8)]
        out["runs"] = runs
        for k in ("frequency_error_hz", "amplitude_rel_error", "latency_ms", "latency_dac_ms", "stop_ms",
                  "stop_dac_ms"):
            out[f"worst_{k}"] = max(r[k] for r in runs)
        for k in ("latency_dac_ms", "stop_dac_ms"):
            out[f"median_{k}"] = statistics.median(r[k] for r in runs)
        out["clock"] = "capture stream time (JACK frame clock)"
        out["goals_ms"] = dict(GOALS_MS)
        out["goals_met"] = {k: bool(out[f"worst_{k}"] <= g) for k, g in GOALS_MS.items()}
        stop = threading.Event()

        def busy() -> None:
            while not stop.is_set():
                sum(i * i for i in range(2000))

        def underruns(c: "VoiceCoilAudio", seconds: float) -> dict:
            """Underruns of coil ``c`` over ``seconds`` of servo-like commands, with the
            busy thread (unless --no-busy) running from before to after. A coil in an
            audio process is measured with this process's PortAudio detached from the
            server (it runs no stream then; its idle JACK client would otherwise be one
            more client in the graph, see JackServer.portaudio_detached)."""
            stop.clear()
            detach = srv.portaudio_detached() if c.isolation == "process" else contextlib.nullcontext()
            with detach:
                log0, late0 = srv.xruns(), srv.late_clients()
                with c:
                    hold(c, 0.5, frequency_hz=150.0, amplitude=0.3)
                    mine = srv.clients()
                    th = threading.Thread(target=busy, daemon=True)
                    if not a.no_busy:
                        th.start()
                    u0, c0 = c.underruns, c.callbacks
                    hold(c, seconds, frequency_hz=150.0, amplitude=0.3)
                    stop.set()
                    res = {"underruns": c.underruns - u0, "callbacks": c.callbacks - c0}
                    if c.isolation == "process":
                        res["audio_process"] = c.audio_process_timing()
                if th.is_alive():
                    th.join()
                res["server_xruns_during"] = srv.xruns() - log0
                late = {k: v - late0.get(k, 0) for k, v in srv.late_clients().items() if v - late0.get(k, 0)}
                res["late_clients"] = late
                res["coil_client"] = mine
                res["coil_client_late"] = sum(late.get(k, 0) for k in mine)
            return res
        out.update(underruns(coil, a.minutes * 60.0))
        if a.reference_seconds > 0:
            out["reference_other_isolation"] = {"isolation": other, "seconds": a.reference_seconds,
                                                **underruns(new_coil(other), a.reference_seconds)}
        with srv.portaudio_detached():   # the C client alone in the graph
            x0, late0 = srv.xruns(), srv.late_clients()
            subprocess.run(["timeout", "-k", "5", "30", "jack_simple_client"], capture_output=True,
                           env={**os.environ, "JACK_DEFAULT_SERVER": srv.name})
            out["reference_c_client_late"] = {k: v - late0.get(k, 0) for k, v in srv.late_clients().items()
                                              if v - late0.get(k, 0)}
        out["reference_c_client_server_xruns_30s"] = srv.xruns() - x0
    out["loadavg_end"] = os.getloadavg()
    if a.json:
        print(json.dumps(out, indent=1))
    else:
        print(f"JACK dummy driver {a.rate} Hz, period {a.period} frames ({a.period / a.rate * 1e3:.2f} ms); "
              f"8 runs at random frequencies and amplitudes, worst of each:")
        print(f"  frequency error {out['worst_frequency_error_hz']:.4f} Hz, amplitude error "
              f"{out['worst_amplitude_rel_error'] * 100:.3f} %")
        print("  on the capture stream's clock (JACK frame time), worst (median) of the 8 runs:")
        for k, what in (("latency", "command-to-sound"), ("stop", "stop-to-silence")):
            goal, met = GOALS_MS[f"{k}_dac_ms"], out["goals_met"][f"{k}_dac_ms"]
            print(f"  {what} {out[f'worst_{k}_ms']:.2f} ms through the loopback, "
                  f"{out[f'worst_{k}_dac_ms']:.2f} ms ({out[f'median_{k}_dac_ms']:.2f} ms) with the output latency: "
                  f"goal <= {goal:g} ms {'met' if met else 'MISSED'}")
        busy_txt = " with a busy Python thread in this process" if not a.no_busy else ""
        print(f"{a.minutes:g} min{busy_txt}, isolation {iso!r}: {out['underruns']} "
              f"underruns in {out['callbacks']} callbacks; the server counted {out['server_xruns_during']} xruns, "
              f"{out['coil_client_late']} of them naming the coil's client late (late clients: "
              f"{out['late_clients'] or 'none'})")
        if out.get("audio_process"):
            ap_ = out["audio_process"]
            print(f"  in the audio process: longest callback {ap_['callback_max_ms']:.2f} ms, "
                  f"{ap_['late_starts']} callbacks started more than 1.5 periods after the previous one "
                  "(over the whole time the coil was open)")
        ref = out.get("reference_other_isolation")
        if ref:
            print(f"reference: isolation {ref['isolation']!r}, {ref['seconds']:g} s right after, same conditions: "
                  f"{ref['underruns']} underruns in {ref['callbacks']} callbacks; the server counted "
                  f"{ref['server_xruns_during']} xruns, {ref['coil_client_late']} naming the coil's client late")
        print(f"reference: JACK's C example client alone, 30 s right after: "
              f"{out['reference_c_client_server_xruns_30s']} server xruns (late clients: "
              f"{out['reference_c_client_late'] or 'none'})")
        la0, la1 = out["loadavg_start"], out["loadavg_end"]
        print(f"load average (1/5/15 min) at the start {la0[0]:.2f}/{la0[1]:.2f}/{la0[2]:.2f}, at the end "
              f"{la1[0]:.2f}/{la1[1]:.2f}/{la1[2]:.2f} on {out['cpus']} CPUs; {a.hogs} CPU hog process(es) "
              f"added; JACK real-time: {out['jack_realtime']} (other processes' load is in these figures)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
