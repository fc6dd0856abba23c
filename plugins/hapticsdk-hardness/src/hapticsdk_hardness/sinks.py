"""Where a simulated vibration actuator's drive waveform goes.

A sink has ``write(samples: np.ndarray)`` (float samples, full scale 1.0) and
``close()``. :func:`make_sink` builds one from a short spec: ``None``/``"buffer"``
(in memory, the last 60 s: :data:`BUFFER_KEEP_S`; the default), ``"wav:PATH"`` (16-bit mono WAV via the stdlib ``wave``
module, written to a temporary file and renamed over PATH on close), a callable (called with each block), ``"sounddevice"`` (an audio output, needs
the optional ``sounddevice`` package, imported only then), or any object with ``write``.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
import wave
from typing import Any, Callable

import numpy as np

from hapticsdk.errors import DeviceNotFoundError, FileWriteError, ValidationError
from hapticsdk.sim.samples import SampleWindow


def _umask() -> int:
    m = os.umask(0)
    os.umask(m)
    return m


class BufferSink:
    """Keeps the newest samples in memory (at least ``keep_samples`` of them; None: every
    sample); :meth:`samples` returns them as one array. ``n``: samples written."""

    def __init__(self, keep_samples: int | None = None) -> None:
        self._window = SampleWindow(keep_samples)

    @property
    def n(self) -> int:
        """Samples written since creation or :meth:`clear`."""
        return self._window.total

    def write(self, samples: np.ndarray) -> None:
        """Keep a block of drive samples (-1..1)."""
        self._window.append(samples)

    def samples(self) -> np.ndarray:
        """The samples kept, oldest first, as one array."""
        return self._window.samples()

    def clear(self) -> None:
        """Forget the samples kept."""
        self._window.clear()

    def close(self) -> None:
        """Nothing to release."""


class WavSink:
    """Writes 16-bit mono PCM at ``fs`` Hz; samples are clipped to [-1, 1].

    The samples go to a temporary file next to ``path``; :meth:`close` completes the WAV
    header, flushes it to disk and renames it over ``path``. So ``path`` only ever holds
    a complete WAV: the old file stays as it was when a write failed (disk full, file
    size limit), when the process is killed, or when :meth:`discard` is called; a
    symbolic link at ``path`` is replaced, not written through.
    """

    def __init__(self, path: str, fs: float) -> None:
        from hapticsdk.fileio import check_output_path

        self.path = str(path)
        self.fs = int(round(fs))
        target = check_output_path(self.path, field="sink")  # missing folder, a directory: now
        self.failed = False
        self.n = 0
        try:
            fd, self._tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp",
                                             dir=str(target.parent) or ".")
        except OSError as exc:
            raise FileWriteError(f"cannot create a file next to it: {exc.strerror or exc}", field=self.path) from None
        os.chmod(self._tmp, 0o644 & ~_umask())
        self._fh: Any = os.fdopen(fd, "w+b")
        self._w: Any = wave.open(self._fh, "wb")
        self._w.setnchannels(1)
        self._w.setsampwidth(2)
        self._w.setframerate(self.fs)

    def write(self, samples: np.ndarray) -> None:
        """Append a block of drive samples (-1..1, clipped) to the WAV file as 16-bit PCM.
        """
        if self._w is None or not samples.size:
            return
        pcm = np.round(np.clip(samples, -1.0, 1.0) * 32767.0).astype("<i2")
        try:
            self._w.writeframes(pcm.tobytes())
        except BaseException:
            self.failed = True  # the target is not replaced by a partial file
            raise
        self.n += samples.size

    def discard(self) -> None:
        """Drop what was written; ``path`` keeps its old content."""
        self.failed = True
        self.close()

    def __del__(self) -> None:  # never closed (the actuator was never opened): no file
        if getattr(self, "_w", None) is not None:
            with contextlib.suppress(Exception):
                self.discard()

    def close(self) -> None:
        """Finish the WAV and rename it over ``path`` (nothing is replaced after a failed
        write or :meth:`discard`). Raises :class:`FileWriteError` when the final write fails."""
        if self._w is None:
            return
        w, self._w = self._w, None
        ok = False
        try:
            if self.failed:
                with contextlib.suppress(Exception):  # into the temporary file, removed below
                    w.close()
            else:
                w.close()  # header with the frame count; the file object stays open
                self._fh.flush()
                os.fsync(self._fh.fileno())
            self._fh.close()
            if not self.failed:
                os.replace(self._tmp, self.path)
                ok = True
        except OSError as exc:
            raise FileWriteError(f"WAV not written, the old file is unchanged: {exc.strerror or exc}",
                                 field=self.path) from None
        finally:
            if not ok:
                with contextlib.suppress(OSError):
                    self._fh.close()
                with contextlib.suppress(OSError):
                    os.unlink(self._tmp)


class CallbackSink:
    """Calls ``fn(samples)`` with every block."""

    def __init__(self, fn: Callable[[np.ndarray], Any]) -> None:
        self.fn = fn
        self.n = 0

    def write(self, samples: np.ndarray) -> None:
        """Hand a block of drive samples (-1..1) to the callback."""
        if samples.size:
            self.fn(samples)
            self.n += samples.size

    def close(self) -> None:
        """Nothing to release."""


class SoundDeviceSink:
    """Streams to an audio output through the optional ``sounddevice`` package."""

    def __init__(self, fs: float, device: Any = None) -> None:
        from .audio import import_sounddevice  # noqa: PLC0415  (optional library, imported lazily)
        # ImportError, or OSError without the PortAudio library: a DeviceNotFoundError naming
        # what to install
        sd = import_sounddevice("voicecoil-virtual")
        stream = None
        try:
            stream = sd.OutputStream(samplerate=fs, channels=1, dtype="float32", device=device)
            stream.start()
        except Exception as exc:  # PortAudioError: no output device, or none that takes this format
            if stream is not None:
                with contextlib.suppress(Exception):
                    stream.close()
            raise DeviceNotFoundError(
                f"the 'sounddevice' sink could not open an audio output at {fs:g} Hz "
                f"({type(exc).__name__}: {exc}); start an audio server or plug in an output, or use "
                "sink='buffer' or 'wav:PATH'", device="voicecoil-virtual") from None
        self._stream = stream
        self.n = 0

    def write(self, samples: np.ndarray) -> None:
        """Play a block of drive samples (-1..1) on the sound card (blocking until queued).
        """
        if samples.size:
            self._stream.write(np.asarray(samples, np.float32).reshape(-1, 1))
            self.n += samples.size

    def close(self) -> None:
        """Stop and close the sound card stream."""
        self._stream.stop()
        self._stream.close()


#: seconds of waveform the default ``"buffer"`` sink keeps (as ``piezo-virtual``'s
#: ``keep_s``): the memory of a live session does not grow with its length
BUFFER_KEEP_S = 60.0


def make_sink(spec: Any, fs: float) -> Any:
    """Build a sink from ``spec`` (see the module doc); ``"buffer"`` keeps the last
    :data:`BUFFER_KEEP_S` seconds at ``fs``."""
    if spec is None or spec == "buffer":
        return BufferSink(max(1, int(BUFFER_KEEP_S * fs)))
    if isinstance(spec, str):
        if spec.startswith("wav:"):
            return WavSink(spec[4:], fs)
        if spec == "sounddevice":
            return SoundDeviceSink(fs)
        raise ValidationError(f"unknown sink {spec!r}; use 'buffer', 'wav:PATH', 'sounddevice', "
                              "a callable or an object with write()", field="sink")
    if hasattr(spec, "write"):
        return spec
    if callable(spec):
        return CallbackSink(spec)
    raise ValidationError(f"cannot use {spec!r} as a sink", field="sink")
