"""What a kit run returns: :class:`Violation` (one broken rule of one plugin), :class:`KitResult`
(the violations, plus the notes and the declared plugin API) and their text."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence






@dataclass(frozen=True)
class Violation:
    """One broken rule of one plugin."""

    kind: str
    plugin: str
    rule: str
    message: str

    def __str__(self) -> str:
        return f"[{self.kind} {self.plugin!r}] rule {self.rule!r}: {self.message}"


class KitResult(list):
    """The violations of one :func:`check` run (a ``list`` of :class:`Violation`, as
    before), plus what the run could not judge and the plugin's declared API:

    * ``notes``: rule -> a sentence, e.g. ``read-back``: the actuator reports its drive
      record, so the rules compared the record, not the physical output;
    * ``api``: ``{"declared": range or None, "where": ..., "provided": PLUGIN_API_VERSION,
      "new_rules": {rule: version}}`` — the kit's rules new since the oldest API version the
      plugin declares (a violation of one of them says so).
    """

    notes: dict[str, str]
    api: dict[str, Any]

    def __init__(self, items: Sequence[Violation] = ()) -> None:
        super().__init__(items)
        self.notes = {}
        self.api = {}


def format_report(result: Sequence[Violation]) -> str:
    """The violations, then the notes and the API line of a :class:`KitResult`."""
    lines = [str(v) for v in result]
    for rule, note in (getattr(result, "notes", None) or {}).items():
        lines.append(f"note ({rule}): {note}")
    api = getattr(result, "api", None) or {}
    if api:
        new = ", ".join(f"{r} ({v})" for r, v in api.get("new_rules", {}).items()) or "none"
        lines.append(f"plugin API: declares {api.get('declared')!r} ({api.get('where')}); this core provides "
                     f"{api.get('provided')}; kit rules new since the declared version: {new}")
    return "\n".join(lines)


def format_violations(violations: Sequence[Violation]) -> str:
    """The violations as text, one per line."""
    return "\n".join(str(v) for v in violations)


def assert_conforms(violations: Sequence[Violation]) -> None:
    """Raise ``AssertionError`` listing every violation (for tests), with the result's
    notes and API line when it is a :class:`KitResult`."""
    if violations:
        raise AssertionError(f"{len(violations)} conformance violation(s):\n" + format_report(violations))
