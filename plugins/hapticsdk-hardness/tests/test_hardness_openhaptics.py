"""omni-openhaptics: library-missing errors, ctypes prototypes, and (when gcc exists) the
real ctypes path against a tiny C stub of libHD built in a temp dir (a STUB, not OpenHaptics)."""

from __future__ import annotations

import ctypes
import shutil
import subprocess
import time
from types import SimpleNamespace

import pytest

from hapticsdk.perception.dimensions import ChannelCommand
from hapticsdk.errors import DeviceError, DeviceNotFoundError
from hapticsdk_hardness import openhaptics as oh


def test_missing_library_error_names_files_tried(monkeypatch, tmp_path):
    monkeypatch.delenv("HAPTICSDK_LIBHD", raising=False)
    monkeypatch.setattr(oh.ctypes.util, "find_library", lambda name: None)
    with pytest.raises(DeviceNotFoundError) as ei:
        oh.OmniOpenHaptics().open()
    msg = str(ei.value)
    assert "libHD.so" in msg or "HD.dll" in msg
    assert "OpenHaptics" in msg and "omni-virtual" in msg and ei.value.device == "omni-openhaptics"
    bogus = str(tmp_path / "nowhere" / "libHD.so")
    with pytest.raises(DeviceNotFoundError) as ei:
        oh.OmniOpenHaptics(library=bogus).open()
    assert bogus in str(ei.value)
    ok, why = oh.OmniOpenHaptics.check_available()
    assert not ok and "libHD" in why


def test_prototypes_are_set():
    fake = SimpleNamespace(**{n: SimpleNamespace() for n in oh.PROTOTYPES})
    oh.bind(fake)
    assert fake.hdGetError.restype is oh.HDErrorInfo and fake.hdGetError.argtypes == []
    assert fake.hdInitDevice.restype is ctypes.c_uint and fake.hdInitDevice.argtypes == [ctypes.c_char_p]
    assert fake.hdScheduleAsynchronous.argtypes == [oh.HDSchedulerCallback, ctypes.c_void_p, ctypes.c_ushort]
    assert fake.hdScheduleAsynchronous.restype is ctypes.c_ulong
    assert fake.hdGetDoublev.argtypes[1] is ctypes.POINTER(ctypes.c_double)
    assert fake.hdSetSchedulerRate.argtypes == [ctypes.c_ulong]
    assert [f[0] for f in oh.HDErrorInfo._fields_] == ["errorCode", "internalErrorCode", "hHD"]
    with pytest.raises(AttributeError):
        oh.bind(SimpleNamespace())


STUB_C = r"""
#include <pthread.h>
#include <string.h>
#include <time.h>
#include <unistd.h>
typedef unsigned int HHD; typedef unsigned int HDenum; typedef unsigned int HDerror;
typedef struct { HDerror errorCode; int internalErrorCode; HHD hHD; } HDErrorInfo;
typedef unsigned int (*CB)(void *);
static HDErrorInfo err_stack[16]; static int n_err = 0;
static CB async_cb = 0; static void *async_data = 0; static volatile int running = 0, cb_live = 0;
static unsigned long rate = 1000; static pthread_t th; static double t0 = 0, last_force[3];
static volatile int inject = 0, force_enabled = 0, in_frame = 0; static volatile long ticks = 0;
static double now(void){ struct timespec ts; clock_gettime(CLOCK_MONOTONIC, &ts); return ts.tv_sec + ts.tv_nsec*1e-9; }
static void push(HDerror c){ if (n_err < 16) { err_stack[n_err].errorCode = c; err_stack[n_err].internalErrorCode = 7; err_stack[n_err].hHD = 1; n_err++; } }
HHD hdInitDevice(const char *name){ if (name && strcmp(name, "Missing") == 0) { push(0x0302); return 0xFFFFFFFFu; } t0 = now(); return 1; }
void hdDisableDevice(HHD h){ force_enabled = 0; }
void hdMakeCurrentDevice(HHD h){}
HHD hdGetCurrentDevice(void){ return 1; }
void hdBeginFrame(HHD h){ in_frame = 1; }
void hdEndFrame(HHD h){ in_frame = 0; if (inject) { push(inject); inject = 0; } }
HDErrorInfo hdGetError(void){ HDErrorInfo e = {0, 0, 0}; if (n_err) { e = err_stack[--n_err]; } return e; }
const char *hdGetErrorString(HDerror c){ return c == 0x0302 ? "communication error (stub)" : "stub error"; }
void hdEnable(HDenum c){ if (c == 0x4000) force_enabled = 1; }
void hdDisable(HDenum c){ if (c == 0x4000) { force_enabled = 0; last_force[0] = last_force[1] = last_force[2] = 0; } }
unsigned char hdIsEnabled(HDenum c){ return c == 0x4000 ? force_enabled : 0; }
void hdGetDoublev(HDenum p, double *v){
  double t = now() - t0;
  switch (p) {
    case 0x2050: v[0] = 80.0 * t; v[1] = 5.0 - 2.0 * t; v[2] = 0; break;   /* mm */
    case 0x2051: v[0] = 80.0; v[1] = -2.0; v[2] = 0; break;               /* mm/s */
    case 0x2603: v[0] = 3.3; break; case 0x2604: v[0] = 0.88; break; case 0x2602: v[0] = 2.31; break;
    case 0x2551: for (int i = 0; i < 6; i++) v[i] = (i < 3 ? -80.0 : 80.0); break;
    default: push(0x0100);
  }
}
void hdGetIntegerv(HDenum p, int *v){ v[0] = 0; }
const char *hdGetString(HDenum p){ return "stub"; }
void hdSetDoublev(HDenum p, const double *v){ if (p == 0x2700 && in_frame) { if (force_enabled) memcpy(last_force, v, sizeof last_force); } }
static void *loop(void *arg){
  while (running) {
    if (cb_live && async_cb) { ticks++; if (async_cb(async_data) == 0) cb_live = 0; }
    usleep((useconds_t)(1000000 / rate));
  }
  return 0;
}
void hdStartScheduler(void){ running = 1; pthread_create(&th, 0, loop, 0); }
void hdStopScheduler(void){ if (running) { running = 0; pthread_join(th, 0); } }
void hdSetSchedulerRate(unsigned long r){ rate = r; }
void hdScheduleSynchronous(CB cb, void *d, unsigned short prio){ cb(d); }
unsigned long hdScheduleAsynchronous(CB cb, void *d, unsigned short prio){ async_cb = cb; async_data = d; cb_live = 1; return 42; }
void hdUnschedule(unsigned long h){ cb_live = 0; async_cb = 0; }
unsigned char hdWaitForCompletion(unsigned long h, unsigned int c){ return cb_live; }
double hdGetSchedulerTimeStamp(void){ return now() - t0; }
/* test helpers */
void stub_last_force(double *v){ memcpy(v, last_force, sizeof last_force); }
void stub_inject_error(unsigned int c){ inject = c; }
long stub_ticks(void){ return ticks; }
int stub_scheduler_running(void){ return running; }
"""


@pytest.fixture(scope="module")
def stub_lib(tmp_path_factory):
    gcc = shutil.which("gcc") or shutil.which("cc")
    if gcc is None:
        pytest.skip("no C compiler to build the libHD stub")
    d = tmp_path_factory.mktemp("libhd")
    src = d / "hdstub.c"
    src.write_text(STUB_C)
    out = d / "libHD.so"
    res = subprocess.run([gcc, "-shared", "-fPIC", "-O1", "-o", str(out), str(src), "-lpthread"],
                         capture_output=True, text=True, timeout=60)
    if res.returncode != 0:
        pytest.skip(f"stub build failed: {res.stderr[:300]}")
    return str(out)


def _hold(dev, force_n, seconds, direction=None):
    """Command like a 1 kHz servo loop for ``seconds``; returns the last command sent."""
    end = time.monotonic() + seconds
    sent = None
    while True:
        sent = dev.command(ChannelCommand("force", force_n=force_n, direction=direction))
        if time.monotonic() >= end:
            return sent
        time.sleep(0.001)


def _dev(stub_lib, **kw):
    from hapticsdk.devices.safety import SafetyLayer
    return oh.OmniOpenHaptics(library=stub_lib, safety=SafetyLayer(oh.OmniOpenHaptics.limits, ramp_time_s=0.0), **kw)


def _force(lib):
    v = (ctypes.c_double * 3)()
    lib.stub_last_force(v)
    return list(v)


def _held_force(dev, lib, force_n, seconds, expected_n, direction=None):
    """Hold ``force_n`` for ``seconds`` as a servo loop would, then the force the device
    wrote, from a hold that no stall of this thread disturbed. On a busy machine this
    thread can stall past 50 ms: within the hold, the safety layer then counts a command
    gap as a fault and gates again (the commands after it send 0 until one passes the
    start gate), and between the last command and the read the device's watchdog writes
    0; both are right, and both are checked on their own elsewhere. So each try first
    passes the start gate (0.5 N, as the test's first hold), and is kept when its last
    command sent ``expected_n`` and the watchdog did not fire; tries again for up to 10 s.
    Returns the last command sent and the force written."""
    end = time.monotonic() + 10.0
    while True:
        _hold(dev, 0.5, 0.01)
        zeroed = dev.watchdog_zeroed
        sent = _hold(dev, force_n, seconds, direction)
        f = _force(lib)
        # the servo counts a zeroing before it writes the zero force, so a force read with
        # the count unchanged was written from a fresh command
        fresh = dev.watchdog_zeroed == zeroed and sent.force_n == pytest.approx(expected_n)
        if fresh or time.monotonic() > end:
            return sent, f


def test_stub_servo_loop_limits_state_force(stub_lib):
    dev = _dev(stub_lib, surface_y_mm=5.0)
    with dev:
        lib = dev.lib
        assert dev.limits.max_force_n == pytest.approx(3.3)                 # read from the device
        assert dev.limits.max_stiffness_n_per_mm == pytest.approx(2.31)
        assert dev.device_info["max_continuous_force_n"] == pytest.approx(0.88)
        _hold(dev, 0.5, 0.01)
        t0, n0 = time.monotonic(), lib.stub_ticks()
        _hold(dev, 1.5, 0.2)
        rate = (lib.stub_ticks() - n0) / (time.monotonic() - t0)
        # the scheduler runs, and never faster than its 1 kHz (how close to 1 kHz it gets on
        # a busy machine is a benchmark's question, not a unit test's)
        assert 0 < rate <= 1100
        _, f = _held_force(dev, lib, 1.5, 0.02, 1.5)
        assert f == [0.0, 1.5, 0.0]                                         # written in the servo frame
        st = dev.read_state()
        assert st.velocity_mm_s.tolist() == [80.0, -2.0, 0.0]
        assert st.position_mm[1] == pytest.approx(-2.0 * st.t, abs=0.05)   # relative to surface_y_mm
        sent, f = _held_force(dev, lib, 9.0, 0.02, 3.3)
        assert sent.force_n == pytest.approx(3.3)                           # safety uses device limits
        assert f[1] == pytest.approx(3.3)
        t0 = time.monotonic()                                               # Python loop stalls:
        while time.monotonic() - t0 < 10.0 and not (_force(lib)[1] == 0.0 and dev.watchdog_zeroed >= 1):
            time.sleep(0.005)                                               # (waits for what it asserts)
        assert _force(lib)[1] == 0.0 and dev.watchdog_zeroed >= 1          # device-side watchdog
    assert lib.stub_scheduler_running() == 0 and _force(lib) == [0.0, 0.0, 0.0]


def test_stub_force_along_a_slanted_normal_is_the_whole_vector(stub_lib):
    """A spatial scene's contact normal (``ChannelCommand.direction``) is rendered as the
    vector ``F n`` in the servo frame: the Omni has three force axes. (It was written along
    y whatever the normal: a box's side face pushed the stylus up.)"""
    dev = _dev(stub_lib, surface_y_mm=5.0)
    with dev:
        lib = dev.lib
        n = (0.6, 0.0, 0.8)
        sent, f = _held_force(dev, lib, 1.5, 0.02, 1.5, direction=n)
        assert f == pytest.approx([0.9, 0.0, 1.2])
        sent, f = _held_force(dev, lib, 1.0, 0.02, 1.0, direction=(-1.0, 0.0, 0.0))
        assert f == pytest.approx([-1.0, 0.0, 0.0])
        assert dev.read_back().force_n == pytest.approx(0.0)     # its y component
    assert _force(lib) == [0.0, 0.0, 0.0]


def test_stub_hd_error_stops_and_names_device(stub_lib):
    dev = _dev(stub_lib, label="omni-left").open()
    lib = dev.lib
    _hold(dev, 0.5, 0.01)
    _, f = _held_force(dev, lib, 2.0, 0.02, 2.0)
    assert f[1] == 2.0
    lib.stub_inject_error(0x0201)
    deadline = time.monotonic() + 2.0
    with pytest.raises(DeviceError) as ei:
        while time.monotonic() < deadline:
            dev.command(ChannelCommand("force", force_n=2.0))
            time.sleep(0.002)
    assert ei.value.device == "omni-left" and "HD_EXCEEDED_MAX_FORCE" in str(ei.value)
    assert _force(lib) == [0.0, 0.0, 0.0] and dev.fault is not None
    with pytest.raises(DeviceError):
        dev.read_state()
    dev.close()
    assert lib.stub_scheduler_running() == 0


def test_stub_init_failure_names_config_and_library(stub_lib):
    with pytest.raises(DeviceNotFoundError) as ei:
        oh.OmniOpenHaptics(library=stub_lib, config="Missing").open()
    msg = str(ei.value)
    assert "'Missing'" in msg and stub_lib in msg and "HD_COMM_ERROR" in msg
