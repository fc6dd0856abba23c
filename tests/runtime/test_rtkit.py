"""Real-time for a normal user through RealtimeKit (issue 27), against real daemons
started here: a dbus-daemon with a system-bus configuration in a temporary directory,
polkitd (in a private mount namespace whose /etc/polkit-1/rules.d is a temporary
directory with one rule granting RealtimeKit's actions) and rtkit-daemon, all on that
bus. The live session runs as the unprivileged user ``nobody``: SCHED_FIFO is refused
by the OS, RealtimeKit grants SCHED_RR. Needs root (to start the daemons and switch
user) and the Debian packages dbus, rtkit and polkitd; skips naming them elsewhere,
fails under CI=true."""

import contextlib
import os
import shutil
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

import pytest

RTKIT = "/usr/libexec/rtkit-daemon"
POLKITD = "/usr/lib/polkit-1/polkitd"
ROOT = Path(__file__).resolve().parents[2]


def _need(ok, why):
    if not ok:
        if os.environ.get("CI") == "true":
            pytest.fail(why)
        pytest.skip(why)


BUS_CONF = """<!DOCTYPE busconfig PUBLIC "-//freedesktop//DTD D-Bus Bus Configuration 1.0//EN"
 "http://www.freedesktop.org/standards/dbus/1.0/busconfig.dtd">
<busconfig>
  <type>system</type>
  <listen>unix:path={sock}</listen>
  <auth>EXTERNAL</auth>
  <policy context="default">
    <allow user="*"/>
    <allow own="*"/>
    <allow send_destination="*"/>
    <allow receive_sender="*"/>
  </policy>
</busconfig>
"""
RULE = """polkit.addRule(function(action, subject) {
    if (action.id.indexOf("org.freedesktop.RealtimeKit1.") == 0) { return polkit.Result.YES; }
});
"""


#: held while the modes of ``_traversable`` are changed: two test runs on one machine
#: (two checkouts, one interpreter under /root) each restored /root's mode while the
#: other's ``nobody`` was still importing from under it
_TRAVERSE_LOCK = Path(tempfile.gettempdir()) / "hapticsdk-tests-traversable.lock"


@contextlib.contextmanager
def _traversable(paths):
    """For the test's duration, let others *traverse* (o+x, never read or list) the
    directories above ``paths`` that forbid it (a Python under /root, a virtual
    environment in a 0700 temporary directory), so that ``nobody`` can run this very
    interpreter and import the packages under test; restored afterwards. Serialised
    across processes (an exclusive lock on a file in the temporary directory): another
    run's restore cannot take the way away while this one's child runs."""
    import fcntl
    changed = []
    lock = open(_TRAVERSE_LOCK, "a")
    fcntl.flock(lock, fcntl.LOCK_EX)
    try:
        for p in paths:
            d = Path(p)
            for a in [d, *d.parents]:
                if a.is_dir():
                    mode = a.stat().st_mode
                    if not mode & 0o001:
                        os.chmod(a, (mode & 0o7777) | 0o001)
                        changed.append((a, mode & 0o7777))
        yield
    finally:
        try:
            for a, mode in reversed(changed):
                os.chmod(a, mode)
        finally:
            lock.close()   # releases the lock


class Bus:
    """A system bus of our own, with polkitd (optionally) and rtkit-daemon on it."""

    def __init__(self, polkit: bool) -> None:
        self.dir = Path(tempfile.mkdtemp(prefix="hapticsdk-rtkit-"))
        os.chmod(self.dir, 0o755)  # nobody reaches the socket and the script
        self.sock = self.dir / "system_bus_socket"
        (self.dir / "system.conf").write_text(BUS_CONF.format(sock=self.sock))
        self.env = {**os.environ, "DBUS_SYSTEM_BUS_ADDRESS": f"unix:path={self.sock}"}
        self.procs = []
        self.procs.append(subprocess.Popen(["dbus-daemon", "--config-file", str(self.dir / "system.conf"),
                                            "--nofork"], stderr=subprocess.DEVNULL))
        self._wait(lambda: self.sock.exists(), "dbus-daemon socket")
        os.chmod(self.sock, 0o777)
        if polkit:
            rules = self.dir / "rules"
            rules.mkdir()
            (rules / "50-hapticsdk-test.rules").write_text(RULE)
            os.chmod(rules, 0o755)
            os.chmod(rules / "50-hapticsdk-test.rules", 0o644)
            self.procs.append(subprocess.Popen(
                ["unshare", "--mount", "--propagation", "private", "sh", "-c",
                 f"mount --bind {rules} /etc/polkit-1/rules.d && exec {POLKITD} --no-debug"],
                env=self.env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        # rtkit-daemon sets RLIMIT_FSIZE 0 for itself: its stderr must be a pipe, not a file
        self.rtkit = subprocess.Popen([RTKIT, "--stderr", "--no-canary"], env=self.env,
                                      stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
        self.procs.append(self.rtkit)
        sys.path.insert(0, str(ROOT))
        from hapticsdk.runtime import rtkit
        old = os.environ.get("DBUS_SYSTEM_BUS_ADDRESS")
        os.environ["DBUS_SYSTEM_BUS_ADDRESS"] = self.env["DBUS_SYSTEM_BUS_ADDRESS"]
        try:
            self._wait(lambda: "error" not in rtkit.properties() or self.rtkit.poll() is not None,
                       "rtkit-daemon on the bus")
            self.props = rtkit.properties()
        finally:
            if old is None:
                os.environ.pop("DBUS_SYSTEM_BUS_ADDRESS", None)
            else:
                os.environ["DBUS_SYSTEM_BUS_ADDRESS"] = old

    def _wait(self, pred, what, timeout=10.0):
        t0 = time.monotonic()
        while time.monotonic() - t0 < timeout:
            if pred():
                return
            time.sleep(0.02)
        raise AssertionError(f"{what} did not come up within {timeout} s")

    def run_as_nobody(self, code: str) -> subprocess.CompletedProcess:
        script = self.dir / "app.py"
        script.write_text(textwrap.dedent(code))
        os.chmod(script, 0o644)
        # nobody's own per-user folders: the suite's temporary home (0700, root's) is not
        # readable by nobody, so every XDG folder it names is replaced, not only the cache
        env = {k: v for k, v in self.env.items() if not k.startswith("XDG_")}
        env.update({"HOME": str(self.dir), "XDG_CACHE_HOME": str(self.dir / "cache"),
                    "XDG_CONFIG_HOME": str(self.dir / "config"), "XDG_DATA_HOME": str(self.dir / "data"),
                    "XDG_STATE_HOME": str(self.dir / "state"), "PYTHONPATH": str(ROOT)})
        (self.dir / "cache").mkdir(exist_ok=True)
        os.chmod(self.dir / "cache", 0o777)  # nobody's cache (amortised tables)
        with _traversable([os.path.realpath(sys.executable), sys.prefix, str(ROOT)]):
            return subprocess.run(["setpriv", "--reuid=nobody", "--regid=nogroup", "--clear-groups",
                                   sys.executable, str(script)], env=env, capture_output=True, text=True,
                                  timeout=300, cwd=str(self.dir))

    def close(self):
        for p in reversed(self.procs):
            if p.poll() is None:
                p.terminate()
                try:
                    p.wait(5)
                except subprocess.TimeoutExpired:
                    p.kill()
        shutil.rmtree(self.dir, ignore_errors=True)


@pytest.fixture
def bus(request):
    _need(os.geteuid() == 0, "needs root to start dbus-daemon, polkitd and rtkit-daemon and to switch user")
    for exe, pkg in (("dbus-daemon", "dbus"), (RTKIT, "rtkit"), (POLKITD, "polkitd"), ("setpriv", "util-linux"),
                     ("unshare", "util-linux")):
        _need(shutil.which(exe) or os.path.exists(exe), f"{exe} missing (Debian package {pkg})")
    try:
        import jeepney  # noqa: F401
    except ImportError:
        _need(False, "jeepney missing (pip install 'hapticsdk[rt]')")
    b = Bus(polkit=getattr(request, "param", True))
    yield b
    b.close()


APP = """
import os
import hapticsdk as hs
from hapticsdk.sim.finger import Trajectory
PAD = {"schema_version": 1, "name": "pad",
       "objects": [{"name": "pad", "material": {"intensities": {"hardness": 0.5}}}],
       "devices": {"force": "probe-virtual"}, "settings": {"solver": {"seed": 0}}}
if __name__ == "__main__":
    assert os.geteuid() != 0
    tr = Trajectory([(0.0, 0.0, 2.0), (0.3, 0.0, -1.0), (600.0, 0.0, -1.0)])
    with hs.Session(PAD, trajectory=tr) as s:
        import time
        time.sleep(0.3)
        pol = os.sched_getscheduler(s.servo_pid) & 0xFF
        summary = s.close()
    print("POLICY", pol)
    print("RT", summary["report"]["rt"]["rt_priority"])
"""


def test_a_normal_user_gets_real_time_from_realtimekit(bus):
    assert bus.props.get("MaxRealtimePriority", 0) >= 1, bus.props
    out = bus.run_as_nobody(APP)
    assert out.returncode == 0, out.stderr[-3000:]
    rt = out.stdout.split("RT ", 1)[1].strip()
    prio = bus.props["MaxRealtimePriority"]
    assert rt.startswith(f"applied: SCHED_RR {prio} via RealtimeKit"), rt
    assert f"POLICY {os.SCHED_RR}" in out.stdout  # the servo process's policy, read from outside


@pytest.mark.parametrize("bus", [False], indirect=True)
def test_without_polkit_the_refusal_is_named_and_the_servo_runs(bus):
    """No polkitd on the bus: RealtimeKit cannot authorise; the session still runs, at
    normal priority, and says why (the daemon's D-Bus error)."""
    out = bus.run_as_nobody(APP)
    assert out.returncode == 0, out.stderr[-3000:]
    rt = out.stdout.split("RT ", 1)[1].strip()
    assert rt.startswith("refused: EPERM") and "RealtimeKit refused: org.freedesktop" in rt, rt
    assert "normal priority" in rt
    assert f"POLICY {os.SCHED_OTHER}" in out.stdout


def test_the_servo_goes_back_to_normal_scheduling_cleanly(bus):
    """After the run the servo thread leaves real time (the loop's restore): with
    RealtimeKit's SCHED_RESET_ON_FORK, which an unprivileged thread may not clear, a
    plain SCHED_OTHER request is refused; the restore keeps the flag."""
    out = bus.run_as_nobody(APP)
    assert out.returncode == 0, out.stderr[-3000:]
    assert "could not undo a realtime option" not in out.stderr, out.stderr[-2000:]
