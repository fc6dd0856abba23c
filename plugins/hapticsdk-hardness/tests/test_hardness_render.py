"""Hardness plugin: formula (8) measured on the simulated Omni (goal 7), formula (7)
reproduced by the voice coil's actual waveform (goal 8), constraint (4), plugins."""

import functools
import wave

import numpy as np
import pytest

from hapticsdk.calibration import VoiceCoilCalibration
from hapticsdk.errors import DeviceNotFoundError, ValidationError
from hapticsdk.passivity import ControllerSettings, colgate_stiffness_n_per_mm
from hapticsdk.plugins import registry
from hapticsdk.runtime import ServoLoop
from hapticsdk.sim.finger import Trajectory
from hapticsdk_hardness.dimension import GS_MAX_N_PER_MM, HardnessDimension, HardnessRenderer, WorkConstraint
from hapticsdk_hardness.omni import OmniVirtual
from hapticsdk_hardness.voicecoil import VoiceCoilVirtual


def _slow_press(depth_mm=3.0, speed=5.0):
    """Rest 2 mm above (the safety ramp finishes), press at `speed` mm/s (< 10: quasi-static), release."""
    s = (2.0 + depth_mm) / speed
    return Trajectory([(0, 0, 2.0), (0.3, 0, 2.0), (0.3 + s, 0, -depth_mm), (0.4 + s, 0, -depth_mm),
                       (0.4 + 2 * s, 0, 2.0)])


@functools.lru_cache(maxsize=None)
def _measured_damping():
    """The simulated Omni's damping measured hands off (the finger taken away), as a lab
    does once per arm before rendering stiff walls (docs/calibration.md): the default
    controller credits none of a declared damping, and without it the arm's 2.3 N/mm is
    beyond what the energy bound holds through a press (docs/runtime.md, Passivity item 2)."""
    from hapticsdk.calibration.damping import DampingCalibration, measure_damping
    from hapticsdk.sim.finger import FingerParams
    free = OmniVirtual(finger=FingerParams(0.0, 0.0, 0.0))
    fit, _, _ = measure_damping(free)
    return DampingCalibration.from_fit(fit, period_s=1e-3, resolution_mm=free.encoder_resolution_mm,
                                       generated=True, source="test: simulated Omni, hands off")


def _press_log(gs, finger, measured=True):
    tr = _slow_press()
    dev = OmniVirtual(trajectory=tr, finger=finger)
    r = HardnessDimension().renderer({"GS": gs})
    settings = ControllerSettings.for_device(dev, damping=_measured_damping()) if measured else None
    loop = ServoLoop(dev, [r], {"force": dev, "coil": VoiceCoilVirtual()}, passivity_settings=settings)
    rep = loop.run(tr.duration_s)
    # the loading branch: the press and the hold (the reference stops at 0.4 + s)
    load = rep.log["t"] < tr.duration_s - (tr.duration_s - 0.4) / 2
    # the loop's own Colgate spring (N/mm): 2 b_lo / T of the damping its controller
    # credits (none of a declaration, docs/runtime.md, Passivity item 2)
    return rep.log, load, colgate_stiffness_n_per_mm(loop.passivity_settings, loop.period_s)


@pytest.mark.parametrize("gs", [0.08, 0.3, 0.8, 1.5, 2.3, 4.5])
def test_rendered_force_follows_the_spring_law(gs):
    """Goal 7: press the simulated Omni through the servo loop (passivity on, the arm's
    damping measured hands off first), regress the
    force the arm applied on the measured penetration while the finger presses and holds:
    slope within 7 % of min(GS, 2.3). On the release the force lies between the wall's
    law and the controller's Colgate spring, min(GS, 2 b_lo / T) x penetration (the
    energy-bounded extra above the spring may be let go early; docs/runtime.md)."""
    L, load, k_c = _press_log(gs, "stiff")
    pen, f = L["penetration_mm"], L["force_n"]
    m = (pen > 0.1) & (f < 0.95 * 3.3) & (np.abs(L["velocity_mm_s"][:, 1]) < 60) & load
    assert m.sum() > 200
    slope = np.polyfit(pen[m], f[m], 1)[0]
    assert slope == pytest.approx(min(gs, GS_MAX_N_PER_MM), rel=0.07)
    assert f.max() <= 3.3
    rel = ~load & (pen > 0)
    wall = np.minimum(min(gs, GS_MAX_N_PER_MM) * pen[rel], 3.3)
    spring = np.minimum(min(gs, GS_MAX_N_PER_MM, k_c) * pen[rel], 3.3)
    assert (f[rel] <= wall * (1 + 1e-9)).all()
    assert (f[rel] >= spring * (1 - 1e-9)).all()


@pytest.mark.parametrize("measured", [True, False], ids=["measured", "declared"])
@pytest.mark.parametrize("gs", [0.3, 0.8, 1.5, 2.3])
@pytest.mark.parametrize("finger", ["medium", "soft"])
def test_lighter_fingers_get_at_least_the_passive_spring(gs, finger, measured):
    """A lighter finger bounces on contact; the wall above the passive spring is then
    withheld as far as the energy bound needs, never the spring itself: on every contact
    tick the force is at least min(GS, 2 b_lo / T) x penetration and at most the wall."""
    L, _, k_c = _press_log(gs, finger, measured)
    assert (k_c > 0) == measured     # a declared damping alone gives no spring
    pen, f = L["penetration_mm"], L["force_n"]
    c = pen > 0
    assert (f[c] >= np.minimum(min(gs, k_c) * pen[c], 3.3) * (1 - 1e-9)).all()
    assert (f[c] <= np.minimum(min(gs, GS_MAX_N_PER_MM) * pen[c], 3.3) * (1 + 1e-9)).all()


def test_stiffness_above_the_limit_goes_to_the_coil_never_to_the_arm():
    r = HardnessRenderer(4.0)
    assert r.omni_stiffness_n_per_mm == 2.3 and r.coil_stiffness_n_per_mm == pytest.approx(1.7)
    assert r.rendered_stiffness_n_per_mm() == pytest.approx(4.0)
    from hapticsdk.perception.dimensions import TickInput
    out = {c.role: c for c in r.tick(TickInput(0, 1e-3, 1.0, np.zeros(3), True))}
    assert out["force"].force_n == pytest.approx(2.3)
    assert out["coil"].amplitude > 0
    off = {c.role: c for c in r.tick(TickInput(0, 1e-3, -1.0, np.zeros(3), False))}
    assert off["force"].force_n == 0 and off["coil"].amplitude == 0
    r2 = HardnessRenderer(2.0)
    assert r2.coil_frequency_hz is None and r2.rendered_stiffness_n_per_mm() == 2.0


def _measured_frequency(y, fs):
    """Frequency (Hz) from the spacing of upward zero crossings (linear interpolation)."""
    s = np.signbit(y)
    idx = np.nonzero(s[:-1] & ~s[1:])[0]
    tc = idx + y[idx] / (y[idx] - y[idx + 1])
    return (len(tc) - 1) / ((tc[-1] - tc[0]) / fs)


@pytest.mark.parametrize("f_target", [30.0, 75.0, 120.0])
def test_voice_coil_reproduces_formula_7(f_target):
    """GS = 2.3 + GS_coil(f): the renderer picks f (1e-9 relative) and the coil's
    synthesised 5 kHz waveform, rendered through the loop while pressing, has that frequency."""
    cal = VoiceCoilCalibration.paper()
    gs_coil = 0.00012 * f_target ** 2 + 0.01 * f_target - 0.3045
    r = HardnessDimension().renderer({"GS": GS_MAX_N_PER_MM + gs_coil}, calibration=cal)
    assert r.coil_frequency_hz == pytest.approx(f_target, rel=1e-9)
    assert abs(r.coil_residual_n_per_mm) < 1e-9
    tr = Trajectory([(0, 0, 1.0), (0.2, 0, -2.0), (1.4, 0, -2.0), (1.6, 0, 1.0)])
    dev = OmniVirtual(trajectory=tr, finger="stiff")
    coil = VoiceCoilVirtual()
    ServoLoop(dev, [r], {"force": dev, "coil": coil}).run(tr.duration_s)
    y = coil.sink.samples()
    assert y.size == pytest.approx(tr.duration_s * 5000, abs=10)
    steady = y[int(0.4 * 5000):int(1.3 * 5000)]
    assert _measured_frequency(steady, 5000.0) == pytest.approx(f_target, rel=0.005)
    assert np.abs(steady).max() == pytest.approx(0.5, rel=0.02)  # constant amplitude in contact
    assert np.abs(y[-200:]).max() < 1e-12  # silent after release


def test_coil_clamps_and_reports_residual():
    lo = HardnessRenderer(2.3 + 0.05)
    assert lo.coil_frequency_hz == 30.0 and lo.coil_residual_n_per_mm == pytest.approx(0.05 - 0.1035)
    hi = HardnessRenderer(2.3 + 3.0)
    assert hi.coil_frequency_hz == 120.0 and hi.coil_residual_n_per_mm == pytest.approx(3.0 - 2.6235)


def test_work_constraint_formula_4():
    c = WorkConstraint()
    gs = np.array([0.5, 1.0, 2.0, 0.0])
    wv = 3.3 ** 2 / (2 * gs[:3])
    w = np.r_[wv[0] + 0.1, wv[1] - 0.5, wv[2], 1.0]
    pen = c.penalty({"GS": gs, "W": w})
    assert pen[0] == 0 and pen[2] == 0
    assert pen[1] == pytest.approx(wv[1] ** 2 - (wv[1] - 0.5) ** 2)
    assert np.isinf(pen[3]) or pen[3] > 1e6
    dim = HardnessDimension()
    assert [f.name for f in dim.features] == ["GS", "W"]
    assert isinstance(dim.constraints()[0], WorkConstraint)
    with pytest.raises(ValidationError):
        dim.renderer({"W": 1.0})


def test_entry_points():
    assert registry("dimension").load("hardness") is HardnessDimension
    assert registry("actuator").load("omni-virtual") is OmniVirtual
    assert registry("actuator").load("voicecoil-virtual") is VoiceCoilVirtual
    assert HardnessDimension.default_actuators == {"force": "omni-virtual", "coil": "voicecoil-virtual"}


def test_voicecoil_sinks(tmp_path):
    from hapticsdk.perception.dimensions import ChannelCommand
    path = tmp_path / "coil.wav"
    got = []
    for sink in (f"wav:{path}", got.append):
        c = VoiceCoilVirtual(sink=sink, sample_rate_hz=8000.0)
        c.open()
        for k in range(100):
            c.command(ChannelCommand("coil", frequency_hz=100.0, amplitude=0.8), now=k * 1e-3)
            c.step(1e-3)
        c.close()
    with wave.open(str(path), "rb") as w:
        assert w.getframerate() == 8000 and w.getnframes() == 800 and w.getsampwidth() == 2
    assert sum(len(a) for a in got) == 800
    with pytest.raises(ValidationError):
        VoiceCoilVirtual(sink="nonsense")


@pytest.mark.parametrize("failure", [None, OSError("cannot load library 'libportaudio.so.2'")])
def test_sounddevice_sink_without_the_library_names_what_to_install(monkeypatch, failure):
    """Without sounddevice (not installed: ``sys.modules`` entry None; or installed without
    the PortAudio library: its import raises OSError) the sink is a DeviceNotFoundError
    naming what to install, whether or not sounddevice is installed here."""
    import importlib
    import sys

    if failure is None:
        monkeypatch.setitem(sys.modules, "sounddevice", None)   # import -> ImportError
    else:
        real = importlib.import_module

        def fake(name, *a, **k):
            if name == "sounddevice":
                raise failure
            return real(name, *a, **k)
        monkeypatch.delitem(sys.modules, "sounddevice", raising=False)
        monkeypatch.setattr(importlib, "import_module", fake)
    with pytest.raises(DeviceNotFoundError, match="sounddevice") as err:
        VoiceCoilVirtual(sink="sounddevice")
    assert "libportaudio2" in str(err.value)


@pytest.mark.parametrize("fails_at", ["open", "start"])
def test_sounddevice_sink_without_an_output_is_a_named_error(monkeypatch, fails_at):
    """sounddevice and PortAudio present but no output to open (no audio server, as on a
    headless machine; PortAudio says "Error querying device -1"): a DeviceNotFoundError
    naming the sink and the alternatives, not PortAudio's own exception; a stream opened
    but not started is closed."""
    import sys
    import types

    class PortAudioError(Exception):
        pass

    closed = []

    class Stream:
        def __init__(self, **kw):
            if fails_at == "open":
                raise PortAudioError("Error querying device -1")

        def start(self):
            raise PortAudioError("Invalid sample rate")

        def close(self):
            closed.append(True)
    fake = types.ModuleType("sounddevice")
    fake.OutputStream = Stream
    fake.PortAudioError = PortAudioError
    monkeypatch.setitem(sys.modules, "sounddevice", fake)
    with pytest.raises(DeviceNotFoundError, match="could not open an audio output") as err:
        VoiceCoilVirtual(sink="sounddevice")
    assert "PortAudioError" in str(err.value) and "wav:PATH" in str(err.value)
    assert closed == ([True] if fails_at == "start" else [])


def test_omni_stale_command_becomes_zero():
    """step() applies only what the safety layer says is current: no command -> no force."""
    dev = OmniVirtual(trajectory=Trajectory([(0, 0, -1.0), (1, 0, -1.0)]), encoder_resolution_mm=0.0)
    dev.open()
    dev.step(1e-3)
    assert dev.read_state().force_n[1] == 0.0


def test_press_force_constraint_bounds_the_implied_press():
    from hapticsdk_hardness.dimension import HardnessDimension, PressForceConstraint

    c = PressForceConstraint(6.0)
    gs = np.array([1.0, 1.0, 2.0])
    w = np.array([17.0, 19.0, 9.0])        # implied force sqrt(2 GS W): 5.83, 6.16, 6.0 N
    pen = c.penalty({"GS": gs, "W": w}, "normalised")
    assert pen[0] == 0.0 and pen[2] == 0.0 and pen[1] > 0.0
    assert pen[1] == pytest.approx((19.0 - 18.0) / 19.0)
    names = [k.name for k in HardnessDimension().constraints()]
    assert names == ["hardness.work"]
    names = [k.name for k in HardnessDimension().constraints(press_force_max_n=6.0)]
    assert names == ["hardness.work", "hardness.press_force"]


def test_a_calibration_of_another_kind_is_a_named_error():
    """A renderer option ``calibration`` holding another calibration kind (a piezo table's
    dict) is refused naming the field, in the renderer and through a scene (it was an
    AttributeError of the renderer, reported as a broken plugin)."""
    from hapticsdk.compiler import compile_scene
    from hapticsdk.errors import ValidationError
    from hapticsdk_hardness.dimension import HardnessRenderer
    table = pytest.importorskip("hapticsdk_roughness.table")
    d = table.resolve_table().to_dict()
    with pytest.raises(ValidationError) as ei:
        HardnessRenderer(5.0, calibration=d)
    assert ei.value.field == "calibration" and "PiezoTable" in str(ei.value)
    scene = {"objects": [{"material": {"name": "h", "intensities": {"hardness": 1.0}}}],
             "settings": {"renderer_options": {"hardness": {"calibration": d}}}}
    with pytest.raises(ValidationError) as ei:
        compile_scene(scene)
    assert ei.value.field.startswith("scene.settings.renderer_options.hardness.calibration")
