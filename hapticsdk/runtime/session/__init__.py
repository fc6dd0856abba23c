"""Live haptic sessions: the servo loop runs apart from the application, materials and
objects change while a person touches them.

:class:`Session` compiles a scene, starts the servo (by default in its own process,
``isolation="process"``; ``"thread"`` runs it in a thread of the application's process,
for tests and pure simulation), and returns at once. The servo side owns the devices:
it opens the scene's actuators, runs :class:`~hapticsdk.runtime.loop.ServoLoop` on the
machine clock (every command through the safety layer and the passivity controller)
and closes them. The application side never blocks on the servo:

* :meth:`Session.state` reads the latest probe position, velocity, force, the object in
  contact and tick statistics from shared memory (a seqlock: the servo bumps a sequence
  number before and after each write; a reader retries while it is odd or changed);
* :meth:`Session.events` drains the event ring (contact enter/leave with the object's
  name, renderer errors, clamps, overruns, skipped ticks, material switches, faults);
* :meth:`Session.set_material`, :meth:`add_object`, :meth:`remove_object`,
  :meth:`move_object` send a message on a pipe. :meth:`Session.set_material` builds
  the new renderers in the application (as the servo would: same settings, actuator
  options, capabilities and calibrations) and sends them pickled, so the servo only
  unpickles them (a calibration table they hold, such as the piezo's 300 kB drive
  table, crosses the pipe once per session and is referred to afterwards, so a
  switch unpickles about a kilobyte); renderers that cannot be pickled here go as features, and the servo
  builds them. The servo process has one thread of its own: it reads the pipe without
  blocking, before each sleep of its clock and after each tick, and does a command's
  work in the slack left before the next deadline (:mod:`.servo`); the new
  renderers take over at the start of the next tick, and ``state().switched_at`` says
  when;
* :meth:`pause`, :meth:`resume` and :meth:`close` set flags in shared memory.

Live retargeting: :meth:`Session.set_material` answers new intensities at once with the
amortised inverse (the ``amortised`` solver of ``hapticsdk-ga``, a table lookup of about
a millisecond) and sends those features; a background thread of the application then
solves again with the scene's solver (``settings.solver.method``) and, when the answer
differs, sends the refined features. The servo switches by the loop's rule
(:meth:`~hapticsdk.runtime.loop.ServoLoop.set_renderers`, docs/runtime.md, "Material
switch"): a force the new material raises keeps its value and takes the new slope (no
step), one it lowers is ramped over ``ramp_s`` (default 50 ms, at most 0.1 N per tick),
vibration amplitudes are ramped too, and the passivity controller of the force channel
runs across the switch unchanged. Each switch is acknowledged: the returned
:class:`Retarget` waits (:meth:`Retarget.wait`) for the tick that rendered it first
(:class:`~hapticsdk.runtime.callbacks.SwitchHandle`). :meth:`Session.on_event` runs
callbacks on an application thread the SDK owns; ``Session(record=...)`` streams every
tick to disk (:mod:`hapticsdk.runtime.recorder`).

Failure semantics (each one tested in ``tests/runtime/test_session.py``):

* the application process dies (SIGKILL, or SIGTERM/SIGHUP with no handler): the servo
  process checks every tick that its parent is still its parent and that the command
  pipe still has a writer (end of file once the application's descriptors are closed),
  and watches the heartbeat an application thread writes every 10 ms; any one lost
  stops every actuator (``heartbeat_timeout_s``, default 0.25 s, for a hung
  application; the parent and pipe checks answer within a tick of the kernel tearing
  the application down) and the servo exits. (``prctl(PR_SET_PDEATHSIG)`` is not used:
  the kernel sends it at the same moment the parent check sees the new parent, and it
  also fires when the *thread* that started the servo ends while the application
  lives on);
* the servo process dies: the next call on the session raises
  :class:`~hapticsdk.errors.ServoProcessDied` with the reason (exit status, signal,
  device fault);
* SIGINT, SIGTERM or SIGHUP to the servo process: safe stop (every actuator stopped,
  devices closed, shared memory released by the application's ``close()``), the servo
  exits with ``128 + signal``; to the application: Ctrl-C raises ``KeyboardInterrupt``
  whose ``with`` exit calls :meth:`close`, and the default SIGTERM/SIGHUP kill the
  application, which the servo notices as above;
* a renderer raising: counted (``renderer_error`` events and ``state().renderer_errors``);
* :meth:`close` always leaves every actuator stopped, the servo process reaped and the
  shared-memory segment unlinked (also after any of the above).

Only the standard library crosses the process boundary (``multiprocessing`` with the
``spawn`` start method, ``multiprocessing.shared_memory``, pipes). The servo process
limits its BLAS / OpenMP thread pools to one thread (:mod:`.servo`): a pool
worker that busy-waits between the servo's small matrix calls would take a CPU from
the servo.

The package, one idea per module: :mod:`.protocol` (the shared-memory slots and the
records read from them), :mod:`.pipe` (the command pipe), :mod:`.shipping` (renderers
and their calibration tables across the pipe), :mod:`.servo` (the servo process) and
:mod:`.app` (the application's :class:`Session`). This module is the public home of
their public names.
"""

from .app import ISOLATIONS, Retarget, Session, session
from .protocol import (
    CLAMP_FIELDS, CLAMP_REPORT_S, EVENT_KINDS, HEARTBEAT_PERIOD_S, SessionEvent, SessionState, Slots,
)

__all__ = ["CLAMP_FIELDS", "CLAMP_REPORT_S", "EVENT_KINDS", "HEARTBEAT_PERIOD_S", "ISOLATIONS",
           "Retarget", "Session", "SessionEvent", "SessionState", "Slots", "session"]
