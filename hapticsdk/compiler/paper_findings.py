"""The leave-out rule against the reference paper's findings on its 8 evaluated samples.

The paper rated realism with every component rendered and with one removed, for S1, S2,
S7, S12, S13, S14, S16 and S20 (section 4), and reports (section 5.1) for which samples
removing a component made a statistically significant difference:

* removing roughness: S1, S7, S13, S14, S16;
* removing hardness: S2, S12, S13, S14, S16, S20.

A decision agrees when the plan keeps a dimension whose removal was significant, or
drops one whose removal was not: 16 sample-dimension pairs. Two kinds of disagreement
differ in weight: a **drop where the paper found a significant loss** contradicts the
paper; a **keep where it found none** is the conservative rule at work (a difference that
10 raters did not show significant is not evidence that the loss is small).

The library's samples are GENERATED data anchored to the paper's stated orderings, not
the paper's samples: the comparison says how the rule behaves on that stand-in, not how
it would on the real ones.
"""

from __future__ import annotations

from typing import Any, Mapping

__all__ = ["EVALUATED", "SIGNIFICANT", "compare_with_paper", "format_comparison", "paper_comparison_scene"]

#: the paper's evaluated samples, in its order
EVALUATED: tuple[str, ...] = ("S1", "S2", "S7", "S12", "S13", "S14", "S16", "S20")
#: removal -> samples where the realism difference to "All" was significant (section 5.1)
SIGNIFICANT: dict[str, frozenset[str]] = {
    "roughness": frozenset({"S1", "S7", "S13", "S14", "S16"}),
    "hardness": frozenset({"S2", "S12", "S13", "S14", "S16", "S20"}),
}


def paper_comparison_scene(threshold_percent: float | None = None) -> dict[str, Any]:
    """A scene of the paper's 8 evaluated library samples (hardness + roughness)."""
    settings: dict[str, Any] = {}
    if threshold_percent is not None:
        settings["importance"] = {"threshold_percent": float(threshold_percent)}
    return {"schema_version": 1, "name": "paper-evaluated-samples",
            "objects": [{"name": s, "material": s} for s in EVALUATED], "settings": settings}


def _explain(sample: str, dim: str, e: Mapping[str, Any], significant: bool, dropped: bool) -> str:
    lo, hi = e["interval_percent"]
    thr = e["threshold_percent"]
    if dropped and significant:
        return (f"contradiction: the regression at this sample's (generated) features puts the whole "
                f"interval {lo:.1f}-{hi:.1f} % below {thr:g} %, but the paper found removing {dim} "
                f"significant; the paper's own features of {sample} are not published")
    if not dropped and not significant:
        if lo < thr <= hi:
            return (f"conservative: the interval {lo:.1f}-{hi:.1f} % straddles {thr:g} %, so the rule keeps "
                    f"{dim}; the paper's test found no significant loss, which does not show the loss is small")
        if e.get("decision") == "drop":
            return (f"{dim} judged droppable ({lo:.1f}-{hi:.1f} %) but the other dimension had the lower "
                    f"predicted loss: the regressions are single removals, at most one is dropped")
        return (f"the regression predicts {lo:.1f}-{hi:.1f} % at this sample's (generated) features, above "
                f"{thr:g} %; the paper found no significant loss with 10 raters")
    if dropped:
        return f"agrees: interval {lo:.1f}-{hi:.1f} % wholly below {thr:g} %, paper: not significant"
    return f"agrees: kept ({lo:.1f}-{hi:.1f} %), paper: significant"


def compare_with_paper(plan: Any) -> dict[str, Any]:
    """Per evaluated sample and dimension: the plan's decision, its interval, the paper's
    finding, agreement and an explanation; and the counts. ``plan``: a compiled
    :class:`~hapticsdk.plan.RenderPlan` (or its ``to_dict()``) holding the 8 samples."""
    d = plan.to_dict() if hasattr(plan, "to_dict") else plan
    mats = d["materials"]
    rows = []
    for s in EVALUATED:
        if s not in mats:
            continue
        m = mats[s]
        dropped = {x["dimension"] for x in m.get("dropped", [])}
        for dim in ("roughness", "hardness"):
            e = (m.get("importance") or {}).get(dim)
            if e is None:
                continue
            sig = s in SIGNIFICANT[dim]
            gone = dim in dropped
            rows.append({"sample": s, "dimension": dim, "plan": "drop" if gone else "keep",
                         "median_percent": e["median_percent"], "interval_percent": list(e["interval_percent"]),
                         "threshold_percent": e["threshold_percent"], "paper_significant": sig,
                         "agrees": sig != gone, "contradiction": gone and sig,
                         "explanation": _explain(s, dim, e, sig, gone)})
    return {"rows": rows, "agree": sum(r["agrees"] for r in rows), "total": len(rows),
            "contradictions": sum(r["contradiction"] for r in rows),
            "conservative_keeps": sum((not r["agrees"]) and r["plan"] == "keep" for r in rows),
            "generated": True,
            "note": ("library samples are GENERATED data anchored to the paper's orderings, not the paper's "
                     "samples; the paper's findings: section 5.1 (significant realism loss on removal)")}


def format_comparison(cmp: Mapping[str, Any]) -> str:
    """Text table of :func:`compare_with_paper`."""
    lines = ["leave-out decisions against the paper's findings (8 evaluated samples x 2 removals)",
             "NOTE: " + cmp["note"],
             f"{'sample':<7}{'removal':<11}{'plan':<6}{'80 % interval':>16}  {'paper':<16}agrees"]
    for r in cmp["rows"]:
        lo, hi = r["interval_percent"]
        lines.append(f"{r['sample']:<7}{r['dimension']:<11}{r['plan']:<6}{f'{lo:.1f}-{hi:.1f} %':>16}  "
                     f"{'significant' if r['paper_significant'] else 'not significant':<16}"
                     f"{'yes' if r['agrees'] else 'NO'}")
    lines.append(f"agreement: {cmp['agree']} of {cmp['total']}; drops the paper contradicts: "
                 f"{cmp['contradictions']}; conservative keeps (paper: not significant): {cmp['conservative_keeps']}")
    for r in cmp["rows"]:
        if not r["agrees"]:
            lines.append(f"  {r['sample']} {r['dimension']}: {r['explanation']}")
    return "\n".join(lines)
