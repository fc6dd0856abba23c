"""``bench/bench_hand_motions.py`` runs end to end on a few cells: its table has a row per
kind with the counts it names, the JSON it writes holds every cell with the controller's
figures it counts, and the controller's spent-bound warning (one per controller, i.e.
one per cell here) is counted in the table instead of being printed per cell."""

from __future__ import annotations

import json
import logging

from repo_scripts import load_script


def test_the_hand_motion_bench_counts_what_it_prints(tmp_path, capsys, caplog):
    bench = load_script("bench/bench_hand_motions.py")
    out = tmp_path / "rows.json"
    kinds = bench.KINDS
    with caplog.at_level(logging.WARNING, logger="hapticsdk.passivity.controller"):
        assert bench.main(["--cells", str(2 * len(kinds)), "--seed", "21", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    rows = json.loads(out.read_text())
    assert [r["cell"] for r in rows] == list(range(2 * len(kinds)))
    lines = {ln.split()[0]: ln.split() for ln in text.splitlines() if ln.split() and ln.split()[0] in kinds}
    assert set(lines) == set(kinds)
    for kind in kinds:
        rs = [r for r in rows if r["kind"] == kind]
        cells, over, _emax, _med, below, spent = lines[kind][1:]
        assert int(cells) == len(rs) == 2
        assert int(over) == sum(r["energy_to_user_j"] > bench.ENERGY_BOUND_J for r in rs)
        assert int(below) == sum(r["below_ramp_ticks"] > 0 for r in rs)
        assert int(spent) == sum(r["spent_ticks"] > 0 for r in rs)
    # seed 21's first ten cells spend the bound in some of them (else the count is untested)
    assert any(r["spent_ticks"] > 0 for r in rows)
    assert not [r for r in caplog.records if "energy bound is spent" in r.getMessage()]
