"""Contact gate hysteresis (issue 27): a probe resting at a surface, whose reading flips
between two adjacent encoder counts, never toggles contact (nor the voice coil, whose
gate is the contact); away from the surface the rendered force is unchanged."""

import numpy as np
import pytest

from hapticsdk.perception.dimensions import ChannelCommand, DimensionRenderer
from hapticsdk.runtime import ServoLoop
from hapticsdk.sim.finger import Trajectory
from hapticsdk.sim.probe import VirtualProbe

Q = 0.055  # mm: one count of the simulated Omni's encoder


class Encoded(VirtualProbe):
    """A probe that declares an encoder count (the loop takes its hysteresis from it)."""
    encoder_resolution_mm = Q


class Gate(DimensionRenderer):
    """Force k * penetration and a coil driven while in contact (the hardness renderer's gates)."""
    roles = ("force",)

    def __init__(self):
        self.on = []

    def tick(self, inp):
        self.on.append(inp.in_contact)
        return [ChannelCommand("force", 2.0 * inp.penetration_mm if inp.in_contact else 0.0)]


def _flicker(n=400, rng=None):
    """Rest at the surface: each tick the reading is one of two adjacent counts, the
    surface between them (a random split of the count), in random order."""
    rng = rng or np.random.default_rng(0)
    a = rng.uniform(0.0, Q)  # depth of the deeper count level
    ys = np.where(rng.random(n) < 0.5, -a, Q - a)
    return Trajectory([(0.0, 0.0, 2.0), (0.1, 0.0, ys[0])] + [(0.1 + 1e-3 * (i + 1), 0.0, y) for i, y in
                                                              enumerate(ys[1:])] + [(600.0, 0.0, ys[-1])])


@pytest.mark.parametrize("seed", range(5))
def test_resting_at_the_surface_never_toggles(seed):
    r = Gate()
    rep = ServoLoop(Encoded(trajectory=_flicker(rng=np.random.default_rng(seed))), [r], passivity=False).run(0.45)
    assert rep.events["contact_changes"] == 1  # entered once, never left
    on = np.array(r.on)
    assert on[np.argmax(on):].all()


def test_without_a_declared_encoder_the_gate_is_exact():
    r = Gate()
    rep = ServoLoop(VirtualProbe(trajectory=_flicker()), [r], passivity=False).run(0.45)
    assert rep.events["contact_changes"] > 20


def test_force_away_from_the_surface_is_unchanged():
    """Pressed deeper than a count and slid: every tick's force equals the gate-free loop's."""
    tr = Trajectory([(0.0, 0.0, 2.0), (0.2, 0.0, -1.5), (0.6, 10.0, -0.5), (1.0, 20.0, 2.0), (600.0, 20.0, 2.0)])
    logs = []
    for cls in (Encoded, VirtualProbe):
        rep = ServoLoop(cls(trajectory=tr), [Gate()], passivity=False).run(1.0)
        logs.append(rep.log)
    pen = logs[0]["penetration_mm"]
    away = (pen > 0) | (pen <= -Q)
    assert away.sum() > 900
    assert np.array_equal(logs[0]["force_n"][away], logs[1]["force_n"][away])


def _piezo():
    from hapticsdk_roughness.dimension import RoughnessRenderer
    return RoughnessRenderer(200.0, 2.0)


def _inp(v_raw, v_filt, step, t=0.0):
    from hapticsdk.perception.dimensions import TickInput
    return TickInput(t, 1e-3, 1.0, np.array([v_raw, 0.0, 0.0]), True, (0.0, 1.0, 0.0), "o", (v_filt, 0.0, 0.0), step)


@pytest.mark.parametrize("seed", range(5))
def test_piezo_speed_gate_holds_through_count_level_chatter(seed):
    """A quantised probe sliding just above the 20 mm/s gate: the raw backward
    difference jumps by whole counts per tick, the filtered speed dithers by less than
    one count's step below the gate: the piezo opens once and stays on."""
    rng = np.random.default_rng(seed)
    r = _piezo()
    step = 0.17 * Q / 1e-3  # a 30 Hz first-order filter at 1 kHz, one 0.055 mm count
    on = []
    for k in range(2000):
        vf = r.v_gate_mm_s + 0.5 - rng.uniform(0.0, 0.95 * step)
        raw = rng.choice([0.0, Q / 1e-3])
        on.append(r.tick(_inp(raw, vf, step, k * 1e-3))[0].amplitude > 0)
    on = np.array(on)
    assert np.count_nonzero(np.diff(on.astype(int))) <= 1
    # and the same chatter without the hysteresis (an exact position's gate) toggles
    r0 = _piezo()
    on0 = [r0.tick(_inp(rng.choice([0.0, Q / 1e-3]), 0.0, 0.0))[0].amplitude > 0 for _ in range(200)]
    assert np.count_nonzero(np.diff(np.array(on0, int))) > 20


def test_piezo_commands_away_from_the_gate_are_unchanged():
    """Well above the gate (and with no quantisation), the hysteresis changes nothing:
    frequency follows the raw speed (formula 9) and the amplitude is V_out."""
    for v in (30.0, 55.0, 120.0):
        a = _piezo().tick(_inp(v, v, 9.0))[0]
        b = _piezo().tick(_inp(v, v, 0.0))[0]
        assert (a.frequency_hz, a.amplitude) == (b.frequency_hz, b.amplitude) and a.amplitude > 0


class _Flicker3(VirtualProbe):
    """Resting on a surface, every axis reading one of its two adjacent counts (q mm),
    drawn at random each tick."""

    def __init__(self, q, p0, seed):
        super().__init__()
        self.encoder_resolution_mm = q
        self._lo = np.floor(np.asarray(p0) / q) * q
        self._q = q
        self._rng = np.random.default_rng(seed)

    def _read_state(self):
        from hapticsdk.devices.actuators import DeviceState
        p = self._lo + self._q * (self._rng.random(3) < 0.5)
        return DeviceState(t=self.t, position_mm=p, velocity_mm_s=np.zeros(3))


class _Plane:
    """A hit tester: the plane through the origin with outward unit normal n."""

    def __init__(self, n):
        self.n = np.asarray(n, float) / np.linalg.norm(n)

    def query(self, x, y, z):
        nx, ny, nz = (float(c) for c in self.n)
        return 0, -(x * nx + y * ny + z * nz), nx, ny, nz


@pytest.mark.parametrize("seed", range(25))
def test_resting_on_a_tilted_surface_never_toggles(seed):
    """Any count size, any period, any orientation of the surface against the encoder
    axes: the readings of a probe resting on it (each axis flipping between two
    counts) never end a contact once made."""
    rng = np.random.default_rng(seed)
    q = float(np.exp(rng.uniform(np.log(0.001), np.log(1.0))))        # count (mm)
    period_ms = float(np.exp(rng.uniform(np.log(0.25), np.log(10.0))))  # period (ms)
    plane = _Plane(rng.normal(size=3))
    p0 = rng.uniform(-1.0, 1.0, 3)
    p0 -= (p0 @ plane.n) * plane.n  # on the surface
    rep = ServoLoop(_Flicker3(q, p0, seed), [Gate()], passivity=False, hit_tester=plane,
                    period_s=period_ms * 1e-3).run(200 * period_ms * 1e-3)
    assert rep.events["contact_changes"] <= 1


class _Seen(DimensionRenderer):
    """Records what the renderers are handed: (in_contact, penetration, speed step)."""
    roles = ("force",)

    def __init__(self):
        self.seen = []

    def tick(self, inp):
        self.seen.append((inp.in_contact, inp.penetration_mm, inp.speed_step_mm_s))
        return [ChannelCommand("force", 0.0)]


@pytest.mark.parametrize("seed", range(5))
def test_inside_the_band_renderers_get_the_surface(seed):
    """Held in contact by the hysteresis, a renderer is handed penetration 0 (the
    surface's own value), never the negative reading."""
    r = _Seen()
    ServoLoop(Encoded(trajectory=_flicker(rng=np.random.default_rng(seed))), [r], passivity=False).run(0.45)
    held = [p for c, p, _ in r.seen if c]
    assert held and min(held) >= 0.0
    assert any(p == 0.0 for p in held)   # the band was entered


@pytest.mark.parametrize("q, period_s", [(0.055, 1e-3), (0.01, 2.5e-4), (0.2, 1e-2), (0.03, 4e-3)])
def test_speed_step_is_one_count_through_the_filter(q, period_s):
    """TickInput.speed_step_mm_s: a count q in one tick is a backward difference of q/T;
    a first-order low-pass at f_c passes the fraction 1 - exp(-2 pi f_c T) of a step in
    one tick."""
    class Dev(VirtualProbe):
        encoder_resolution_mm = q

    r = _Seen()
    ServoLoop(Dev(trajectory=Trajectory([(0.0, 0.0, -1.0), (600.0, 0.0, -1.0)])), [r], passivity=False,
              period_s=period_s, velocity_filter_hz=30.0).run(5 * period_s)
    a = 1.0 - np.exp(-2.0 * np.pi * 30.0 * period_s)
    assert [s for _, _, s in r.seen] == pytest.approx([a * q / period_s] * 5, rel=1e-12)


def test_speed_step_follows_the_band_on_the_next_run():
    """The filter's coefficient and speed step are derived at the start of each run: a
    band changed between two runs of one loop is the one the second run hands out."""
    r = _Seen()
    loop = ServoLoop(Encoded(trajectory=Trajectory([(0.0, 0.0, -1.0), (600.0, 0.0, -1.0)])), [r], passivity=False)
    loop.run(0.003)
    loop.contact_hysteresis_mm = 2 * Q
    loop.run(0.003)
    steps = [s for _, _, s in r.seen]
    assert steps[3:] == pytest.approx([2 * steps[0]] * 3, rel=1e-12)
