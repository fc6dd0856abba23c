"""``voicecoil-audio`` measured through a JACK loopback, for as long as you like (the
issue's underrun goal: 10 minutes with a busy application thread).

``python bench/bench_voicecoil_audio.py [--minutes 10] [--period 128] [--rate 48000]
[--no-busy] [--json]``

Needs Debian ``jackd2`` and ``libportaudio2`` and ``pip install hapticsdk-hardness[audio]``.
It starts a private JACK server on its dummy driver (real-time scheduling when allowed),
opens the coil on it with the callback stream, and captures the output back through a
loopback port (:mod:`hapticsdk_hardness.audio_loopback`).

What it measures, on the same capture clock: (1) frequency error, amplitude error
against ``amplitude x full_scale``, command-to-sound and stop-to-silence times, over 8
runs at random frequencies (20..1000 Hz) and amplitudes (0.1..1; seeded) -- the worst of
each is printed; times through the loopback, and with the output's reported latency
added (``dac``); (2) underruns counted by the stream while a servo-like thread commands
the coil every 1 ms and (unless ``--no-busy``) another Python thread computes without
pause, for ``--minutes``; the JACK server's own xrun count over the same time is printed
beside it, and the same count for JACK's C example client (``jack_simple_client``) over
30 s right after, as the reference of what this machine gives a client that needs no
Python interpreter lock.

What it does not measure: a sound card's converters (the dummy driver has none), an
amplifier or the coil.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import subprocess
import sys
import threading
import time


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--period", type=int, default=128, help="JACK period (frames)")
    ap.add_argument("--rate", type=int, default=48000)
    ap.add_argument("--no-busy", action="store_true")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    from hapticsdk.safety import SafetyLayer
    from hapticsdk_hardness.audio import VoiceCoilAudio
    from hapticsdk_hardness.audio_loopback import JackServer, LoopbackCapture, hold, measure
    why = JackServer.available()
    if why:
        print(f"missing: {why}", file=sys.stderr)
        return 2
    rng = random.Random(a.seed)
    out: dict = {"rate": a.rate, "period": a.period, "minutes": a.minutes, "busy": not a.no_busy}
    with JackServer(rate=a.rate, period=a.period) as srv:
        coil = VoiceCoilAudio(device="system", safety=SafetyLayer(VoiceCoilAudio.limits, ramp_time_s=0.0))
        with LoopbackCapture(srv) as cap, coil:
            cap.route()
            runs = [measure(coil, cap, frequency_hz=rng.uniform(20, 1000), amplitude=rng.uniform(0.1, 1.0),
                            seconds=0.5) for _ in range(8)]
        out["runs"] = runs
        for k in ("frequency_error_hz", "amplitude_rel_error", "latency_ms", "latency_dac_ms", "stop_ms",
                  "stop_dac_ms"):
            out[f"worst_{k}"] = max(r[k] for r in runs)
        stop = threading.Event()

        def busy() -> None:
            while not stop.is_set():
                sum(i * i for i in range(2000))
        log0 = srv.xruns()
        with coil:
            hold(coil, 0.5, frequency_hz=150.0, amplitude=0.3)
            th = threading.Thread(target=busy, daemon=True)
            if not a.no_busy:
                th.start()
            u0, c0 = coil.underruns, coil.callbacks
            hold(coil, a.minutes * 60.0, frequency_hz=150.0, amplitude=0.3)
            stop.set()
            out["underruns"] = coil.underruns - u0
            out["callbacks"] = coil.callbacks - c0
        out["server_xruns_during"] = srv.xruns() - log0
        x0 = srv.xruns()
        subprocess.run(["timeout", "30", "jack_simple_client"], capture_output=True,
                       env={**os.environ, "JACK_DEFAULT_SERVER": srv.name})
        out["reference_c_client_server_xruns_30s"] = srv.xruns() - x0
    if a.json:
        print(json.dumps(out, indent=1))
    else:
        print(f"JACK dummy driver {a.rate} Hz, period {a.period} frames ({a.period / a.rate * 1e3:.2f} ms); "
              f"8 runs at random frequencies and amplitudes, worst of each:")
        print(f"  frequency error {out['worst_frequency_error_hz']:.4f} Hz, amplitude error "
              f"{out['worst_amplitude_rel_error'] * 100:.3f} %")
        print(f"  command-to-sound {out['worst_latency_ms']:.2f} ms through the loopback "
              f"({out['worst_latency_dac_ms']:.2f} ms with the output latency)")
        print(f"  stop-to-silence {out['worst_stop_ms']:.2f} ms through the loopback "
              f"({out['worst_stop_dac_ms']:.2f} ms with the output latency)")
        print(f"{a.minutes:g} min{' with a busy Python thread' if not a.no_busy else ''}: {out['underruns']} "
              f"underruns in {out['callbacks']} callbacks; the server counted {out['server_xruns_during']} xruns")
        print(f"reference: JACK's C example client, 30 s right after: {out['reference_c_client_server_xruns_30s']} "
              "server xruns")
        print("(shared machines: other processes' load is in these figures)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
