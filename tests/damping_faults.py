"""A simulated device made to fail mid-run, shared by the hands-off damping run's exit
tests (``tests/calibration/test_calibration_damping.py``, ``test_damping_realtime.py``).

Importable as ``damping_faults`` through ``tests/conftest.py``."""


def fail_at_step(dev, at, exc):
    """Make ``dev.step`` raise ``exc("... mid-run")`` at its ``at``-th call and record the
    force of every command sent to ``dev``: returns that list (the last entry is the last
    force sent)."""
    calls = [0]
    real_step = dev.step

    def failing_step(dt):
        calls[0] += 1
        if calls[0] == at:
            raise exc("simulated fault mid-run")
        real_step(dt)

    dev.step = failing_step
    sent = []
    real_command = dev.command

    def record(cmd, **kw):
        sent.append(cmd.force_n)
        return real_command(cmd, **kw)

    dev.command = record
    return sent
