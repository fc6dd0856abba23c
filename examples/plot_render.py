"""Render a material and save a figure of the run (needs matplotlib).

    python examples/plot_render.py S12 render.png
"""

import sys

import hapticsdk as hs
from hapticsdk.plotting import plot_render

name = sys.argv[1] if len(sys.argv) > 1 else "S12"
path = sys.argv[2] if len(sys.argv) > 2 else "render.png"
report = hs.render(name, seconds=3.0)
print("saved", plot_render(report, path))
