"""Roughness dimension: constraint (5), renderer (9), generated Tab, piezo-virtual output."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from hapticsdk.perception.dimensions import TickInput
from hapticsdk.errors import CalibrationError, ValidationError
from hapticsdk_roughness.dimension import DEFAULT_DF_HZ, RoughnessDimension
from hapticsdk_roughness.table import generated_table, load_table, model_acceleration, save_table
from hapticsdk_roughness.virtual import PiezoVirtual


def tick(vx: float, t: float = 0.0, contact: bool = True) -> TickInput:
    return TickInput(t=t, dt=0.001, penetration_mm=1.0 if contact else -1.0,
                     velocity_mm_s=np.array([vx, 0.0, 0.0]), in_contact=contact)


def test_dimension_contract():
    dim = RoughnessDimension()
    space = dim.feature_space()
    assert space.names == ("Fpeak", "AFpeak", "P")
    assert space["Fpeak"].upper < 250.0
    assert dim.default_actuators == {"vibration": "piezo-virtual"}
    assert set(dim.render_features) == {"Fpeak", "AFpeak"}


def test_power_constraint_formula_5():
    dim = RoughnessDimension()
    (c,) = dim.constraints(df_hz=2.0)
    a = np.array([1.0, 3.0, 3.0])
    p = np.array([5.0, 17.0, 19.0])          # bound = a^2 * 2 = 2, 18, 18
    pen = c.penalty({"AFpeak": a, "P": p}, "paper")
    np.testing.assert_allclose(pen, [0.0, 18.0 ** 2 - 17.0 ** 2, 0.0])
    np.testing.assert_allclose(c.violation({"AFpeak": a, "P": p}), [0.0, 1 / 18, 0.0])
    (d,) = dim.constraints()
    assert d.df_hz == DEFAULT_DF_HZ
    with pytest.raises(ValidationError) as ei:
        dim.constraints(df_hz=0.0)
    assert ei.value.field == "df_hz"


def test_renderer_formula_9_and_gate():
    r = RoughnessDimension().renderer({"Fpeak": 100.0, "AFpeak": 2.0, "P": 9.0})
    v_out = r.v_out
    assert r.in_table and 0 < v_out < 100
    # Tab closed loop: the table predicts AFpeak at Fpeak for V_out
    assert r.table.acceleration_at(100.0, v_out) == pytest.approx(2.0, rel=1e-6)
    for vx in (20.0, -40.0, 80.0, 160.0):
        (c,) = r.tick(tick(vx))
        assert c.role == "vibration"
        assert c.frequency_hz == pytest.approx(100.0 * abs(vx) / 80.0)
        assert c.amplitude == pytest.approx(v_out)
    for vx in (0.0, 19.9, -19.9):
        (c,) = r.tick(tick(vx))
        assert c.amplitude == 0.0
    (c,) = r.tick(tick(100.0, contact=False))
    assert c.amplitude == 0.0
    assert r.describe()["active_ticks"] == 4


def test_out_of_table_is_clamped_and_reported():
    dim = RoughnessDimension()
    r = dim.renderer({"Fpeak": 20.0, "AFpeak": 40.0})     # far beyond 100 V at 20 Hz
    d = r.describe()
    assert d["table_clamped"] and not d["table_in_range"]
    assert r.v_out == pytest.approx(100.0)
    assert d["achieved_AFpeak_m_s2"] < 40.0
    r.tick(tick(50.0))
    r.tick(tick(5.0))
    assert r.describe()["table_clamps"] == 1
    r2 = dim.renderer({"Fpeak": 240.0, "AFpeak": 1.0}, frequency_range_hz=(10.0, 300.0))
    r2.tick(tick(200.0))                                   # f_p = 600 Hz > 300
    (c,) = r2.tick(tick(80.0))
    assert c.frequency_hz == pytest.approx(240.0)
    assert r2.describe()["frequency_clamps"] == 1
    with pytest.raises(ValidationError):
        dim.renderer({"Fpeak": 100.0})


def test_generated_table_is_marked_and_file_roundtrip(tmp_path):
    t = generated_table()
    assert t.generated and "GENERATED" in t.source
    np.testing.assert_allclose(t.acceleration[:, -1], model_acceleration(t.frequencies_hz, 100.0))
    # resonance near f0: acceleration/volt peaks above 200 Hz, below the 500 Hz grid end
    per_volt = t.acceleration[:, -1] / 100.0
    assert 200.0 < t.frequencies_hz[np.argmax(per_volt / (2 * np.pi * t.frequencies_hz) ** 2)] < 300.0
    # a user's "measured" table: half the acceleration -> twice the voltage
    meas = t.to_dict()
    meas.update(acceleration_m_s2=(t.acceleration * 0.5).tolist(), generated=False, source="bench 2026-11-01")
    path = tmp_path / "tab.json"
    path.write_text(json.dumps(meas))
    user = load_table(path)
    assert not user.generated
    r_gen = RoughnessDimension().renderer({"Fpeak": 100.0, "AFpeak": 1.0})
    r_user = RoughnessDimension().renderer({"Fpeak": 100.0, "AFpeak": 1.0}, table=str(path))
    assert r_user.v_out == pytest.approx(2 * r_gen.v_out, rel=0.02)
    assert save_table(t, tmp_path / "g.json").exists()
    assert load_table(tmp_path / "g.json").generated
    with pytest.raises(CalibrationError):
        load_table(tmp_path / "missing.json")


def _zero_crossing_freq(v: np.ndarray, fs: float) -> float:
    s = np.signbit(v)
    idx = np.flatnonzero(s[1:] != s[:-1])
    return (len(idx) - 1) / 2.0 / ((idx[-1] - idx[0]) / fs)


def _fft_freq(v: np.ndarray, fs: float) -> float:
    n = 16 * v.size
    spec = np.abs(np.fft.rfft(v * np.hanning(v.size), n))
    return float(np.fft.rfftfreq(n, 1 / fs)[np.argmax(spec)])


def test_virtual_output_follows_speed_and_is_silent_below_gate():
    """Closed loop: renderer -> piezo-virtual -> measured waveform frequency vs Fpeak*|v|/80."""
    fpeak = 120.0
    r = RoughnessDimension().renderer({"Fpeak": fpeak, "AFpeak": 3.0})
    act = PiezoVirtual(gain=1)
    speeds = [40.0, 10.0, -60.0, 15.0, 100.0, 0.0, 130.0, -25.0]   # mm/s, 0.4 s each
    seg_s = 0.4
    with act:
        t = 0.0
        for vx in speeds:
            for _ in range(int(seg_s * 1000)):
                (cmd,) = r.tick(tick(vx, t))
                act.command(cmd, now=t)
                t += 0.001
        tt, v = act.waveform()
        assert act.driving
    assert not act.driving                       # close() stopped it: amplitude ramped to 0
    fs = act.fs
    n_seg = int(seg_s * fs)
    skip = int(0.02 * fs)                        # past the 5 ms ramp
    for i, vx in enumerate(speeds):
        seg = v[i * n_seg + skip:(i + 1) * n_seg]
        if abs(vx) < 20.0:
            assert np.max(np.abs(seg)) == 0.0, f"not silent at {vx} mm/s"
            continue
        expected = fpeak * abs(vx) / 80.0
        assert _zero_crossing_freq(seg, fs) == pytest.approx(expected, rel=0.01)
        assert _fft_freq(seg, fs) == pytest.approx(expected, rel=0.01)
        assert np.max(np.abs(seg)) == pytest.approx(r.v_out, rel=0.01)
    # no clicks: the amplitude envelope changes by at most full scale per 5 ms
    step = act.limits.max_amplitude / (0.005 * fs)
    env_jump = np.max(np.abs(np.diff(v)))
    f_max = fpeak * 130.0 / 80.0
    assert env_jump <= 2 * np.pi * f_max / fs * r.v_out + step + 1e-9
    assert v[-1] == 0.0 or abs(v[-1]) < step


def test_virtual_limits_and_options():
    act = PiezoVirtual(gain=0, quantize=True)
    assert act.limits.max_amplitude == 25.0
    from hapticsdk.perception.dimensions import ChannelCommand
    with act:
        sent = act.command(ChannelCommand("vibration", frequency_hz=3000.0, amplitude=40.0), now=0.0)
        assert sent.amplitude == 25.0 and sent.frequency_hz == pytest.approx(1992.1875)
        assert act.safety.report()["limit_hits"] == {"frequency_range_hz": 1, "max_amplitude": 1}
    with pytest.raises(ValidationError):
        PiezoVirtual(gain=4)
    with pytest.raises(ValidationError):
        PiezoVirtual(ramp_s=0.001)
    with pytest.raises(ValidationError):
        PiezoVirtual(bogus=1)


def test_simulated_path_never_imports_serial_or_usb():
    code = (
        "import sys, numpy as np\n"
        "from hapticsdk.plugins import registry\n"
        "from hapticsdk.perception.dimensions import TickInput\n"
        "dim = registry('dimension').load('roughness')()\n"
        "act = registry('actuator').load('piezo-virtual')()\n"
        "r = dim.renderer({'Fpeak': 100.0, 'AFpeak': 1.0})\n"
        "with act:\n"
        "    for i in range(10):\n"
        "        act.command(r.tick(TickInput(i*1e-3, 1e-3, 1.0, np.array([50.0, 0, 0]), True))[0])\n"
        "bad = [m for m in sys.modules if m.split('.')[0] in ('serial', 'usb')]\n"
        "assert not bad, bad\n"
        "print('ok')\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "ok"
