"""The reference paper's rating experiment (its section 2.2) run against the simulated
device: materials presented in random order, one experiment per dimension (hardness
first, then roughness), each participant rating every sample on a 0..100 scale; the
answers come through a callback and are saved in the format of
``schemas/ratings.schema.json`` (written atomically with :mod:`hapticsdk.fileio`).

    python examples/experiment.py ratings.json                # simulated participants
    python examples/experiment.py ratings.json --ask          # type the answers yourself
    python examples/experiment.py ratings.json --device force=omni-openhaptics

The default participants are simulated (generated data): each rates what the SDK
rendered, the perception model's intensity of the features sent, times 100, plus the
participant's own noise. A lab with a real device swaps in its actuators by name with
``--device ROLE=ACTUATOR`` (``hapticsdk plugins`` lists them) and collects real answers
with ``--ask`` or its own callback.
"""

import argparse
import random
import sys
import time
from typing import Callable

import hapticsdk as hs
from hapticsdk.fileio import atomic_write_json
from hapticsdk.schemas_io import validate
from hapticsdk.sim.finger import press_slide

#: the samples of the paper's realism experiment (its section 4)
SAMPLES = ("S1", "S2", "S7", "S12", "S13", "S14", "S16", "S20")
DIMENSIONS = ("hardness", "roughness")

#: answer(participant, sample, dimension, retarget) -> rating 0..100
Answer = Callable[[str, str, str, "hs.runtime.session.Retarget"], float]


def simulated_participant(seed: int, noise: float = 6.0) -> Answer:
    """A generated participant: the model's intensity of what was rendered, x 100, plus
    Gaussian noise of ``noise`` points, clipped to 0..100."""
    rng = random.Random(seed)

    def answer(participant, sample, dimension, retarget):
        v = 100.0 * retarget.intensities.get(dimension, retarget.targets[dimension]) + rng.gauss(0.0, noise)
        return min(max(v, 0.0), 100.0)
    return answer


def ask(participant, sample, dimension, retarget):
    while True:
        text = input(f"{participant}: rate the {dimension} of what you feel (0 = none, 100 = most): ")
        try:
            v = float(text)
        except ValueError:
            continue
        if 0.0 <= v <= 100.0:
            return v


def run_experiment(session, participants, answer: Answer, present_s: float, seed: int) -> dict:
    rng = random.Random(seed)
    ratings: dict[str, dict[str, list[float]]] = {s: {d: [] for d in DIMENSIONS} for s in SAMPLES}
    for p in participants:
        for d in DIMENSIONS:                      # one experiment per dimension
            order = list(SAMPLES)
            rng.shuffle(order)                    # samples in random order
            for sample in order:
                r = session.set_material("sample", sample)
                time.sleep(present_s)             # the participant presses and slides
                rating = float(answer(p, sample, d, r))
                if not 0.0 <= rating <= 100.0:
                    raise ValueError(f"rating {rating} outside 0..100")
                ratings[sample][d].append(round(rating, 2))
    return ratings


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", help="ratings file to write (ratings.schema.json format)")
    ap.add_argument("--participants", type=int, default=2)
    ap.add_argument("--present", type=float, default=0.3, help="seconds per presentation (the paper: up to 30)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--ask", action="store_true", help="ask for each rating on the terminal")
    ap.add_argument("--device", action="append", default=[], metavar="ROLE=ACTUATOR",
                    help="use this actuator for a role (e.g. force=omni-openhaptics)")
    args = ap.parse_args(argv)
    devices = dict(d.split("=", 1) for d in args.device)
    scene = {"schema_version": 1, "name": "experiment",
             "objects": [{"name": "sample", "material": SAMPLES[0]}], "devices": devices,
             "settings": {"importance": {"enabled": False}, "solver": {"seed": args.seed}}}
    cycle = press_slide(depth_mm=1.5, press_s=0.1, hold_s=0.05, slide_s=0.3, release_s=0.1, rest_s=0.05)
    finger = cycle
    n = args.participants * len(DIMENSIONS) * len(SAMPLES)
    while finger.duration_s < n * args.present + 30.0:
        finger = finger.then(cycle, gap_s=0.01)
    participants = [f"P{i + 1:02d}" for i in range(args.participants)]
    simulated = not args.ask
    with hs.Session(scene, trajectory=finger) as s:
        if simulated:
            answerers = {p: simulated_participant(args.seed * 1000 + i) for i, p in enumerate(participants)}
            answer = lambda p, *a: answerers[p](p, *a)  # noqa: E731
        else:
            answer = ask
        ratings = run_experiment(s, participants, answer, args.present, args.seed)
        st = s.state()
    doc = {"schema_version": 1, "generated": simulated,
           "source": ("examples/experiment.py: simulated participants on simulated devices (generated data)"
                      if simulated else "examples/experiment.py: answers typed by participants"),
           "scale": {"min": 0, "max": 100}, "dimensions": list(DIMENSIONS), "raters": participants,
           "ratings": ratings}
    validate(doc, "ratings")
    atomic_write_json(args.out, doc)
    print(f"{len(SAMPLES)} samples x {len(DIMENSIONS)} dimensions x {len(participants)} participants -> {args.out}"
          + (" (generated data)" if simulated else ""))
    for sample in SAMPLES:
        means = "  ".join(f"{d} {sum(v) / len(v):5.1f}" for d, v in ratings[sample].items())
        print(f"  {sample:4s} {means}")
    print(f"servo: {st.ticks} ticks, {st.material_switches} material switches, {st.renderer_errors} renderer errors")
    return 0


if __name__ == "__main__":
    sys.exit(main())
