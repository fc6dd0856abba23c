"""An actuator that records what its backend gets, shared by the tick tests
(``tests/runtime/test_tick_values.py``, ``test_tick_fast_paths.py``). A subclass sets
``name``, ``channel`` and ``limits``.

Importable as ``recorders`` through ``tests/conftest.py``."""

from hapticsdk.devices.actuators import Actuator


class RecordingActuator(Actuator):
    """Keeps every command its backend receives in ``sent``; stopping does nothing."""

    def __init__(self, **kw):
        super().__init__(**kw)
        self.sent = []

    def _command(self, cmd):
        self.sent.append(cmd)

    def _stop(self):
        pass
