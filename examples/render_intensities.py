"""Render a material given by perceptual intensities instead of a name.

    python examples/render_intensities.py 0.8 0.3
"""

import sys

import hapticsdk as hs

hardness = float(sys.argv[1]) if len(sys.argv) > 1 else 0.8
roughness = float(sys.argv[2]) if len(sys.argv) > 2 else 0.3

report = hs.render({"hardness": hardness, "roughness": roughness}, seconds=2.0, seed=1)
out = report.to_dict()
solve = out["solve"]
print(f"targets hardness {hardness}, roughness {roughness}")
# the solve covers the rendered dimensions only
print("solved for", ", ".join(solve["targets"]) + ":",
      {k: round(v, 4) for k, v in solve["intensities"].items() if k in solve["targets"]},
      f"reached: {solve['success']}, error {solve['error']:.4f}")
print("features:", {k: round(v, 4) for k, v in out["features"].items()})
print("rendered:", ", ".join(out["dimensions"]) or "nothing", "| actuators:", out["actuators"])
# a dimension whose predicted realism loss is small is left out (not rendered): say so
for d in out["dropped"]:
    print(f"left out {d['dimension']} (not rendered): {d['reason']}")
