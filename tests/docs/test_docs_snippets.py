"""Run the python snippets of the developer docs, in order, one namespace per page."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

DOCS = Path(__file__).resolve().parents[2] / "docs"
PAGES = ["app-developers.md", "plugin-authors.md"]


def snippets(page: str) -> list[str]:
    text = (DOCS / page).read_text(encoding="utf-8")
    return re.findall(r"```python\n(.*?)```", text, flags=re.S)


@pytest.mark.parametrize("page", PAGES)
def test_page_snippets_run(page, capsys):
    blocks = snippets(page)
    assert len(blocks) >= 4, f"{page} has too few runnable snippets"
    if page == "plugin-authors.md":
        pytest.importorskip("hapticsdk_warmth", reason="pip install -e examples/hapticsdk-warmth")
    ns: dict = {"__name__": f"docs_{page.replace('-', '_').replace('.', '_')}"}
    for i, code in enumerate(blocks):
        try:
            exec(compile(code, f"{page}[snippet {i}]", "exec"), ns)
        except Exception as exc:  # name the snippet
            raise AssertionError(f"{page} snippet {i} failed: {type(exc).__name__}: {exc}\n{code}") from exc


def test_readme_api_example_runs(capsys):
    """The README's ten-line example of the public API."""
    readme = (DOCS.parent / "README.md").read_text(encoding="utf-8")
    (code,) = re.findall(r"```python\n(.*?)```", readme, flags=re.S)
    assert len([ln for ln in code.splitlines() if ln.strip()]) <= 10
    exec(compile(code, "README.md", "exec"), {"__name__": "readme"})
    out = capsys.readouterr().out
    assert "True" in out and "'ticks'" in out
