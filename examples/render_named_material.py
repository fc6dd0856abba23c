"""Render a named material from the library on simulated devices.

    python examples/render_named_material.py S7
"""

import sys

import hapticsdk as hs

name = sys.argv[1] if len(sys.argv) > 1 else "S7"
material = hs.load_library().get(name)
print(f"{material.name}: {material.label}, targets {dict(material.intensities)}"
      f"{' (generated data)' if material.generated else ''}")

report = hs.render(material.name, seconds=2.0, seed=0)
out = report.to_dict()
print("solved:", {k: round(v, 4) for k, v in out["features"].items()},
      f"error {out['solve']['error']:.4f} in {out['solve']['time_s'] * 1e3:.2f} ms")
print("kept:", out["dimensions"], "dropped:", [d["dimension"] for d in out["dropped"]])
print("actuators:", out["actuators"])
tick = out["tick"]
print(f"servo: {tick['ticks']} ticks, median {tick['median_us']:.1f} us, p99 {tick['p99_us']:.1f} us, "
      f"overruns {tick['overruns']}")
