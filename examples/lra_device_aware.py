"""Device-aware solving: one roughness target, two actuators, each with its own answer.

The roughness renderer turns the solved features (Fpeak, AFpeak) into a drive through a
drive table. A piezo behind a DRV2667 plays 7.8 Hz .. 2 kHz at up to 50 V (gain 1); a
linear resonant actuator (LRA) plays only around its resonance, here 140..260 Hz at up
to 2.5 V. This script defines a simulated LRA (a third-party actuator, registered
in-process: no core change), compiles the SAME target once on each, and prints each
plan's solved features, the device constraints that bind, and the perceptual residual
(target - predicted intensity of what will actually be rendered). Then it renders both
and shows that the LRA was never driven outside its band at the reference speed.

The LRA's drive table is GENERATED from a textbook resonator model (f0 175 Hz, damping
ratio 0.08, 12 m/s^2 per volt at resonance): replace it with your device's measured
response (same format as a piezo table, ``hapticsdk calibrate piezo``).

Run:  python examples/lra_device_aware.py [--roughness 0.75] [--hardness 0.3]
"""

from __future__ import annotations

import argparse
import sys
from typing import Any, ClassVar

import numpy as np

from hapticsdk.devices.actuators import Actuator, ActuatorLimits, DriveCapability
from hapticsdk.calibration import PiezoTable
from hapticsdk.compiler import compile_scene
from hapticsdk.perception.dimensions import ChannelCommand
from hapticsdk.plugins import registry
from hapticsdk.runtime.render import render_plan

F0_HZ, ZETA, A_PER_V_AT_F0 = 175.0, 0.08, 12.0
BAND_HZ = (140.0, 260.0)
MAX_V = 2.5


def lra_table() -> PiezoTable:
    """GENERATED drive table of the LRA model: acceleration (m/s^2) over (Hz, V)."""
    f = np.linspace(BAND_HZ[0], BAND_HZ[1], 61)
    v = np.linspace(0.0, MAX_V, 26)
    r = f / F0_HZ
    gain = (2 * ZETA) / np.sqrt((1 - r ** 2) ** 2 + (2 * ZETA * r) ** 2)   # 1 at resonance
    a = A_PER_V_AT_F0 * gain[:, None] * v[None, :]
    return PiezoTable(f, v, a, generated=True,
                      source=f"GENERATED LRA model (f0 {F0_HZ:g} Hz, zeta {ZETA:g}, {A_PER_V_AT_F0:g} m/s^2/V)")


class LraVirtual(Actuator):
    """A simulated LRA: vibration channel, frequency in Hz, drive amplitude in V."""

    name: ClassVar[str] = "lra-virtual"
    channel: ClassVar[str] = "vibration"
    accepts: ClassVar[dict[str, str]] = {"frequency_hz": "Hz", "amplitude": "V"}
    limits = ActuatorLimits(frequency_range_hz=BAND_HZ, max_amplitude=MAX_V, amplitude_unit="V")
    simulated: ClassVar[bool] = True
    hapticsdk_api: ClassVar[str] = ">=1.1,<2"

    def __init__(self, **options: Any) -> None:
        super().__init__(**options)
        self.out = (0.0, 0.0)
        self.played: list[tuple[float, float]] = []

    def _open(self) -> None:
        self.out = (0.0, 0.0)

    def _command(self, cmd: ChannelCommand) -> None:
        self.out = (cmd.frequency_hz or self.out[0], cmd.amplitude or 0.0)
        if self.out[1] > 0:
            self.played.append(self.out)

    def _stop(self) -> None:
        self.out = (self.out[0], 0.0)

    def _read_back(self) -> ChannelCommand:
        return ChannelCommand("vibration", frequency_hz=self.out[0], amplitude=self.out[1])

    @classmethod
    def capability_for(cls, options: Any = None) -> DriveCapability:
        return DriveCapability("vibration", BAND_HZ, MAX_V, "V", table=lra_table(),
                               source="lra-virtual (generated resonator model)")


def compile_on(actuator: str, targets: dict[str, float]) -> Any:
    scene = {"name": f"on {actuator}", "objects": [{"name": "o", "material": {"name": "m", "intensities": targets}}],
             "devices": {"vibration": actuator}, "settings": {"importance": {"enabled": False}}}
    return compile_scene(scene)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--roughness", type=float, default=0.75, help="target roughness 0..1 (default 0.75)")
    ap.add_argument("--hardness", type=float, default=None, help="also a hardness target (default none)")
    ap.add_argument("--seconds", type=float, default=1.0, help="render time per actuator (s, default 1)")
    args = ap.parse_args(argv)
    targets = {"roughness": args.roughness}
    if args.hardness is not None:
        targets["hardness"] = args.hardness
    registry("actuator").register("lra-virtual", LraVirtual)
    rows = []
    try:
        for act in ("piezo-virtual", "lra-virtual"):
            plan = compile_on(act, targets)
            mp = plan.material()
            dev = mp.device
            cap = dev["capabilities"]["roughness"]["vibration"]
            print(f"{act}: band {cap['frequency_range_hz'][0]:g}-{cap['frequency_range_hz'][1]:g} Hz, "
                  f"max drive {cap['max_drive']:g} {cap['drive_unit']}")
            print(f"  solved: Fpeak {mp.features['Fpeak']:.1f} Hz, AFpeak {mp.features['AFpeak']:.3f} m/s^2 "
                  f"({'reached' if mp.solve['success'] else 'NOT reached'}, model error {mp.solve['error']:.2g})")
            print(f"  predicted roughness {dev['predicted']['roughness']:.4f} vs target {targets['roughness']:.4f}: "
                  f"residual {dev['residual']['roughness']:+.4f}; binding device constraints: "
                  f"{', '.join(dev['binding']) or 'none'}")
            rep = render_plan(plan, seconds=args.seconds)
            r = rep.renderers["roughness"]
            print(f"  rendered: V_out {r['v_out_v']:.3f} V (table: {r['table_source'][:40]}...), table clamped: {r['table_clamped']}, "
                  f"frequency clamps {r['frequency_clamps']} of {r['ticks']} ticks")
            rows.append((act, mp, rep))
    finally:
        registry("actuator").unregister("lra-virtual")
    print("(the perception model and both drive tables are GENERATED data; 'residual' is against the model's "
          "prediction, not a measured perception)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
