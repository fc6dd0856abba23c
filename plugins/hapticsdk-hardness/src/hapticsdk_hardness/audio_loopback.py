"""Measuring ``voicecoil-audio`` through an audio server's loopback (tests and
``bench/bench_voicecoil_audio.py``).

:class:`JackServer` starts a private JACK server (Debian ``jackd2``) with its dummy
driver -- no sound card, a clock at the given rate and period -- under a unique server
name, and points PortAudio at it (``JACK_DEFAULT_SERVER``, PortAudio re-initialised).
:class:`LoopbackCapture` opens a PortAudio input stream on it and connects every
PortAudio output port to that input with ``jack_connect``, so what an output stream of
this process (or of a child process) plays is captured back, sample for sample, each
block stamped with the input stream's own clock.

What the loopback shows: a sample when it leaves the client into the JACK graph, i.e.
the start of the JACK cycle that rendered it. The capture callback's ``currentTime`` is
the start of its own cycle (JACK's frame time, read just after the cycle began); a block
rendered by another client (an audio process, or a child process) in a cycle reaches the
capture in that same cycle (JACK runs a client whose output feeds another one first); a
block rendered by a stream of the capture's own PortAudio client (an output stream in
this process) reaches it one cycle later (a client's own output read back by its input),
so such blocks are stamped one period earlier. (PortAudio's ``inputBufferAdcTime``
subtracts the latency of the capture port the input would read from, the dummy
driver's, which is not this path.) A card adds its playback latency on top (the output
stream's ``latency``; one period for the dummy driver); :func:`measure` reports both.
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import subprocess
import threading
import time
from typing import Any, Callable, Iterator

import numpy as np

from hapticsdk.perception.dimensions import ChannelCommand


#: how long a JACK command-line tool may take (s): a hang guard for a wedged server, not a
#: timing figure (on an idle machine one takes a few ms; a test process at nice 19 next to
#: five CPU-bound ones, whose children and server inherit its niceness, saw jack_lsp take
#: more than 10 s)
TOOL_WAIT_S = 60.0


def _jack(cmd: list[str], server: str) -> subprocess.CompletedProcess:
    return subprocess.run([cmd[0], "-s", server, *cmd[1:]], capture_output=True, text=True, timeout=TOOL_WAIT_S)


class JackServer:
    """A private JACK server on the dummy driver (context manager).

    Args:
        rate: sample rate (Hz).
        period: frames per period.
        realtime: ask for real-time scheduling (``jackd -R``; falls back to none when
            refused).
    """

    def __init__(self, rate: int = 48000, period: int = 128, realtime: bool = True) -> None:
        self.rate, self.period, self.realtime = int(rate), int(period), bool(realtime)
        self.name = f"hapticsdk-{os.getpid()}-{id(self) & 0xffff:x}"
        self.proc: subprocess.Popen | None = None
        self._old_env: str | None = None
        self.log = ""
        self._xruns = 0
        #: xruns by the client named late (see late_clients)
        self.late: dict[str, int] = {}

    @staticmethod
    def available() -> str | None:
        """What is missing to run one (None: nothing)."""
        for exe in ("jackd", "jack_connect", "jack_lsp", "jack_wait"):
            if shutil.which(exe) is None:
                return f"{exe} (Debian package jackd2)"
        try:
            import sounddevice  # noqa: F401
        except Exception as exc:
            return f"sounddevice with PortAudio (pip install sounddevice; Debian libportaudio2): {exc}"
        return None

    def _start(self, rt: bool) -> bool:
        args = ["jackd", "-n", self.name] + (["-R", "-P", "70"] if rt else ["--no-realtime"])
        args += ["-d", "dummy", "-r", str(self.rate), "-p", str(self.period)]
        env = dict(os.environ, JACK_NO_AUDIO_RESERVATION="1")
        self.proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env,
                                     preexec_fn=_die_with_parent)
        self._xruns = 0
        self.late = {}
        threading.Thread(target=self._read_log, args=(self.proc,), daemon=True).start()
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                time.sleep(0.1)   # the log reader drains the output
                return False
            r = _jack(["jack_wait", "-c"], self.name)
            if r.returncode == 0 and "not running" not in r.stdout and "running" in r.stdout:
                return True
            time.sleep(0.1)
        self.stop()
        return False

    def _read_log(self, proc: subprocess.Popen) -> None:
        for line in proc.stdout or ():
            if "XRun" in line:
                self._xruns += 1
                m = re.search(r"client = (.+?) was not finished", line)
                who = m.group(1) if m else "(none named)"
                self.late[who] = self.late.get(who, 0) + 1
            self.log = (self.log + line)[-4000:]

    def xruns(self) -> int:
        """xruns the server has reported so far (its log)."""
        return self._xruns

    def late_clients(self) -> dict[str, int]:
        """xruns so far by the client the server named as not finished in time (a copy).
        An xrun is one for the whole graph: JACK tells every client (PortAudio flags each
        stream's next callback with an underflow), whichever client was late."""
        return dict(self.late)

    @contextlib.contextmanager
    def portaudio_detached(self) -> Iterator[None]:
        """This process's PortAudio leaves the server for the block (its JACK client, a
        member of the graph that an xrun can be charged to, although it runs no stream
        here) and comes back after. For measuring a client in another process alone."""
        import sounddevice as sd
        sd._terminate()
        try:
            yield
        finally:
            sd._initialize()

    def __enter__(self) -> "JackServer":
        if not (self.realtime and self._start(True)) and not self._start(False):
            raise RuntimeError(f"jackd did not start: {self.log[-500:]}")
        self._old_env = os.environ.get("JACK_DEFAULT_SERVER")
        os.environ["JACK_DEFAULT_SERVER"] = self.name
        _reinit_portaudio()
        return self

    def stop(self) -> None:
        """Stop the server."""
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)

    def __exit__(self, *exc: Any) -> None:
        import sounddevice as sd
        sd._terminate()   # PortAudio's JACK client closes while its server still runs
        self.stop()
        if self._old_env is None:
            os.environ.pop("JACK_DEFAULT_SERVER", None)
        else:
            os.environ["JACK_DEFAULT_SERVER"] = self._old_env
        sd._initialize()

    def ports(self) -> list[str]:
        """Every port name of the server."""
        return _jack(["jack_lsp"], self.name).stdout.split()

    def connect(self, a: str, b: str) -> None:
        """Connect port ``a`` to ``b``."""
        _jack(["jack_connect", a, b], self.name)

    def clients(self, pattern: str = r"PortAudio[^:]*:out_\d+$") -> list[str]:
        """Names of the clients owning ports that match ``pattern`` (default: PortAudio
        output ports)."""
        return sorted({p.split(":")[0] for p in self.ports() if re.match(pattern, p)})

    def disconnect(self, a: str, b: str) -> None:
        """Disconnect port ``a`` from ``b``."""
        _jack(["jack_disconnect", a, b], self.name)


def _die_with_parent() -> None:
    """In the child before exec (Linux): SIGTERM when the process that started it dies, so
    a test process that crashes leaves no server behind."""
    try:
        import ctypes
        import signal
        ctypes.CDLL(None).prctl(1, int(signal.SIGTERM))   # PR_SET_PDEATHSIG
    except Exception:
        pass


def _reinit_portaudio() -> None:
    import sounddevice as sd
    sd._terminate()
    sd._initialize()


class LoopbackCapture:
    """Capture what this server's PortAudio outputs play (context manager; see module)."""

    def __init__(self, server: JackServer) -> None:
        import sounddevice as sd
        self.server = server
        self.blocks: list[tuple[float, np.ndarray]] = []
        self._lock = threading.Lock()
        self._cleared = 0   # clear() calls so far
        self._loud: tuple = ((), 0, 0, 0)   # loud_since's count so far (key, blocks, samples, loud)
        self.stream = sd.InputStream(samplerate=server.rate, channels=1, dtype="float32", callback=self._cb)
        self.in_port: str | None = None
        #: JACK cycles between rendering and capture (see the module doc): 1 when the
        #: routed outputs are on the capture's own client, else 0
        self.cycles = 0

    def _cb(self, data: np.ndarray, frames: int, t: Any, status: Any) -> None:
        with self._lock:
            self.blocks.append((float(t.currentTime), data[:, 0].copy()))

    def __enter__(self) -> "LoopbackCapture":
        self.stream.start()
        ins = [p for p in self.server.ports() if re.match(r"PortAudio[^:]*:in_\d+$", p)]
        self.in_port = ins[-1]
        for p in self.server.ports():
            if p.startswith("system:capture"):
                self.server.disconnect(p, self.in_port)
        self.route()
        return self

    def route(self) -> list[str]:
        """Connect every PortAudio output port (new ones too) to the capture input."""
        outs = [p for p in self.server.ports() if re.match(r"PortAudio[^:]*:out_\d+$", p)]
        for p in outs:
            self.server.connect(p, self.in_port or "")
        own = (self.in_port or "").split(":")[0]
        self.cycles = int(bool(outs) and all(p.split(":")[0] == own for p in outs))
        return outs

    def now(self) -> float:
        """The capture stream's clock (s), the clock of the captured blocks."""
        return float(self.stream.time)

    def clear(self) -> None:
        """Forget what was captured."""
        with self._lock:
            self.blocks = []
            self._cleared += 1

    def count(self) -> int:
        """Samples captured so far (since the last :meth:`clear`). A count, not a time:
        every sample counted was rendered before this call."""
        with self._lock:
            return sum(b.size for _, b in self.blocks)

    def wait_for(self, samples: "int | Callable[[], int]", seconds: float = 10.0) -> bool:
        """Wait until at least ``samples`` are captured (False if ``seconds`` passed
        first: the capture stopped running, not a slow machine). ``samples`` may be a
        callable, asked again on each look: a goal that moves while the capture runs."""
        goal = samples if callable(samples) else (lambda: samples)
        deadline = time.monotonic() + seconds
        while self.count() < goal():
            if time.monotonic() > deadline:
                return False
            time.sleep(0.002)
        return True

    def loud_since(self, start: int, level: float) -> int:
        """How many samples captured from index ``start`` on (since the last
        :meth:`clear`) exceed ``level`` in magnitude. Called again with the same
        ``start`` and ``level``, it reads only the blocks captured since (the capture's
        callback shares this thread's interpreter lock: a long count here makes it late)."""
        with self._lock:
            blocks = self.blocks
            key = (self._cleared, start, level)
            _, k, i, n = self._loud if self._loud[0] == key else (key, 0, 0, 0)
            new = blocks[k:]
        for _, b in new:
            if i + b.size > start:
                n += int(np.count_nonzero(np.abs(b[max(0, start - i):]) > level))
            i += b.size
        self._loud = (key, k + len(new), i, n)
        return n

    def signal(self) -> tuple[np.ndarray, np.ndarray]:
        """(t, y): every captured sample with its time on the capture clock."""
        with self._lock:
            blocks = list(self.blocks)
        if not blocks:
            return np.zeros(0), np.zeros(0)
        fs = self.server.rate
        back = self.cycles * self.server.period / fs
        t = np.concatenate([t0 - back + np.arange(b.size) / fs for t0, b in blocks])
        y = np.concatenate([b for _, b in blocks]).astype(float)
        return t, y

    def __exit__(self, *exc: Any) -> None:
        self.stream.stop()
        self.stream.close()


def sine_fit(t: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """(frequency Hz, amplitude) of a steady sine: frequency from the rising zero
    crossings (linear interpolation between samples): whole cycles over their total time,
    leaving out cycles more than 20 % off the median (a gap of silence: a dropout, the
    end of a contact, the device's own silence when its commands stop coming); amplitude
    from the RMS over the same cycles (x sqrt 2), so a gap lowers neither."""
    # strictly negative, then strictly positive: the step y[i+1] - y[i] is > 0, and the
    # edges of a silence (exact zeros, of either sign) are no crossings (a crossing into
    # a gap made a short cycle that the 20 % rule kept); a crossing through a sample
    # that is exactly 0 is missed, which makes one long cycle that the rule leaves out
    idx = np.nonzero((y[:-1] < 0.0) & (y[1:] > 0.0))[0]
    if idx.size < 3:
        return float("nan"), float("nan")
    frac = -y[idx] / (y[idx + 1] - y[idx])
    tc = t[idx] + frac * (t[idx + 1] - t[idx])
    per = np.diff(tc)
    keep = (per > 0) & (np.abs(per / np.median(per) - 1.0) <= 0.2)
    if not keep.any():
        return float("nan"), float("nan")
    f = int(keep.sum()) / float(per[keep].sum())
    # cycle i is y[idx[i] + 1 : idx[i + 1] + 1]; the samples of the kept cycles
    edge = np.zeros(y.size + 1, int)
    np.add.at(edge, idx[:-1][keep] + 1, 1)
    np.add.at(edge, idx[1:][keep] + 1, -1)
    seg = y[np.cumsum(edge)[:-1] > 0]
    return float(f), float(np.sqrt(2.0 * np.mean(seg * seg)))


def hold(act: Any, seconds: float, period_s: float = 0.001, *, frequency_hz: float | None = None,
         amplitude: float | None = None) -> None:
    """Command ``act`` like a servo loop (every ``period_s``) for ``seconds``."""
    end = time.monotonic() + seconds
    c = ChannelCommand("vibration", frequency_hz=frequency_hz, amplitude=amplitude)
    while time.monotonic() < end:
        act.command(c)
        time.sleep(period_s)


def measure(act: Any, cap: LoopbackCapture, *, frequency_hz: float = 250.0, amplitude: float = 0.5,
            seconds: float = 1.0) -> dict[str, float]:
    """One measurement on an open ``voicecoil-audio`` through the loopback: silence,
    then ``amplitude`` at ``frequency_hz`` commanded like a servo loop until ``seconds``
    of sound are captured (counted in loud samples, not timed: a servo stalled past the
    coil's ``command_timeout_s`` is rightly silenced meanwhile, and is held longer; at
    most ``seconds`` + 10 s), then ``stop()``.

    Returns the frequency error (Hz), the amplitude against ``amplitude x full_scale``
    (relative), command-to-sound and stop-to-silence times through the loopback (ms, on
    the capture clock, see the module doc; ``*_dac_ms`` adds the output's reported
    latency), and underruns counted by the stream over the measurement. These times
    include how soon this machine scheduled the processes involved: figures for a
    benchmark (``bench/bench_voicecoil_audio.py``), not for a pass/fail test.

    Also, counted in samples rather than timed (so they do not depend on scheduling):
    ``sound_before_command``, loud samples among those captured before the first
    command (every one of them was rendered before it, while the coil was commanded
    silence, not left to its dead-man's switch); ``samples_after_stop``, loud
    samples captured after the blocks that can be in flight when ``stop()`` returns
    (``in_flight_samples``: the block a stream may be rendering from the old target,
    one more cycle for a stream read back by the capture's own client, and one period
    per xrun the server reported meanwhile, a late cycle delaying or repeating a block);
    ``samples_checked_after_stop``, how many samples that second count looked at."""
    hold(act, 0.1, amplitude=0.0, frequency_hz=frequency_hz)
    cap.clear()
    period = cap.server.period
    deadline = time.monotonic() + 10.0
    # two periods captured before the command, the coil commanded silence all along
    while cap.count() < 2 * period and time.monotonic() < deadline:
        hold(act, 0.002, amplitude=0.0, frequency_hz=frequency_hz)
    n_cmd = cap.count()
    x0 = cap.server.xruns()
    u0 = act.underruns
    t_cmd = cap.now()
    level = 1e-3 * amplitude * act.full_scale
    # the sound is held until ``seconds`` of it are captured, counted in loud samples: a
    # servo (this thread) that a busy machine stalls past the coil's command_timeout_s
    # is silenced by the coil's dead-man's switch (as it must be), and a stall of
    # ``seconds`` may come before the first command; timing the hold on the wall clock
    # then captured too little sound to measure, or none. A coil that does not sound at
    # all is given 10 s (a broken coil, not a slow machine) and measures as NaN.
    want = int(round(seconds * cap.server.rate))
    hold_deadline = time.monotonic() + seconds + 10.0
    while time.monotonic() < hold_deadline:
        hold(act, min(seconds, 0.01), frequency_hz=frequency_hz, amplitude=amplitude)
        if cap.loud_since(n_cmd, level) >= want:
            break
    act.stop()
    t_stop = cap.now()
    n_stop = cap.count()
    time.sleep(0.1)
    # four periods captured after those in flight; each xrun reported meanwhile adds one
    # to those in flight, so the goal moves while we wait (a busy machine: thousands of
    # xruns over one measurement seen at nice 19): waited for until reached, the capture
    # outrunning the xruns, with a hang guard (the capture stopped: 0 samples checked)
    in_flight = 0

    def after_stop() -> int:
        nonlocal in_flight
        in_flight = (2 + (cap.server.xruns() - x0)) * period
        return n_stop + in_flight + 4 * period

    cap.wait_for(after_stop, TOOL_WAIT_S)
    t, y = cap.signal()
    is_loud = np.abs(y) > level
    loud = np.nonzero(is_loud)[0]
    out_lat = float(act.output_latency_s or 0.0)
    counted = {"sound_before_command": int(np.count_nonzero(is_loud[:n_cmd])), "samples_before_command": n_cmd,
               "samples_after_stop": int(np.count_nonzero(is_loud[n_stop + in_flight:])),
               "samples_checked_after_stop": max(0, y.size - n_stop - in_flight), "in_flight_samples": in_flight}
    if loud.size == 0:
        return {"frequency_error_hz": float("nan"), "amplitude_rel_error": float("nan"),
                "latency_ms": float("nan"), "stop_ms": float("nan"), "latency_dac_ms": float("nan"),
                "stop_dac_ms": float("nan"), "underruns": act.underruns - u0, **counted}
    on, off = t[loud[0]], t[loud[-1]]
    ramp = act.ramp_s
    steady = (t > on + ramp + 0.01) & (t < off - 0.01)
    # the frequency per sample at the card's rate: the blocks' capture times carry the
    # scheduling jitter of the capture callback (on a busy machine a few 0.1 ms), the
    # sample count does not (a digital loopback drops no sample without an overrun,
    # and sine_fit leaves out the cycles a dropout lengthens)
    ys = y[steady]
    f, a = sine_fit(np.arange(ys.size) / float(cap.server.rate), ys)
    return {"frequency_error_hz": abs(f - frequency_hz), "frequency_hz": f,
            "amplitude": a, "amplitude_rel_error": abs(a / (amplitude * act.full_scale) - 1.0),
            "latency_ms": (on - t_cmd) * 1e3, "latency_dac_ms": (on - t_cmd + out_lat) * 1e3,
            "stop_ms": max(0.0, off - t_stop) * 1e3, "stop_dac_ms": (max(0.0, off - t_stop) + out_lat) * 1e3,
            "output_latency_ms": out_lat * 1e3, "underruns": act.underruns - u0, **counted}
