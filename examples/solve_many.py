"""Solve every material of the library in one batched call and check each answer
by running the perception model on it (closed loop)."""

import numpy as np

import hapticsdk as hs

lib = hs.load_library()
# one row per target (a list of rows, or a 2-D array); a list of rows is typed as a batch
rows = [[m.intensities["hardness"], m.intensities["roughness"]] for m in lib]
targets = np.array(rows)
batch = hs.solve(rows, dimensions=["hardness", "roughness"], seed=0)
print(f"{len(batch)} targets in {batch.time_s * 1e3:.1f} ms, {int(batch.success.sum())} reached")
model = hs.load_model("default")
for m, target, res in zip(lib, targets, batch):
    G = [[res.x_dict[n] for n in model.feature_names]]
    pred = model.predict(G)[0]
    print(f"{m.name:<4} target {target.round(3)} predicted {pred.round(3)} "
          f"error {res.error:.4f} {'ok' if res.success else 'NOT REACHED'}")
