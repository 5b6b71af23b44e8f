"""docs/MATH.md: every equation tag the code and notebooks use is defined there; README links it."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MATH = ROOT / "docs" / "MATH.md"

#: "eq. (15)", "Eqn. (9), (10)", "eqs. (3)-(4)", "eq. 9/10", "Eq. (11)-(14)" ...
_EQ_REF = re.compile(r"\b[Ee]q(?:n|s|ns)?\.\s*((?:\(?\d+\)?\s*(?:[-–/,]|and)?\s*)+)")
_RANGE = re.compile(r"\(?(\d+)\)?\s*[-–]\s*\(?(\d+)\)?")
_GEN = re.compile(r"\bG([1-9])\b")


def _numbers(span: str) -> set[int]:
    """Equation numbers in a span like "(11)-(14)", "9/10" or "(9), (10)" (ranges expanded)."""
    found = set()
    for a, b in _RANGE.findall(span):
        found |= set(range(int(a), int(b) + 1))
    found |= {int(d) for d in re.findall(r"\d+", span)}
    return found


def _sources() -> list[Path]:
    files = sorted((ROOT / "fault_tolerance").rglob("*.py"))
    files += sorted((ROOT / "notebooks").glob("*.ipynb")) + [ROOT / "README.md"]
    return [f for f in files if f.is_file()]


def used_tags() -> dict[str, set[str]]:
    """Tag ("(15)", "(G2)") -> the files that use it."""
    tags: dict[str, set[str]] = {}
    for path in _sources():
        text = path.read_text(encoding="utf-8")
        for m in _EQ_REF.finditer(text):
            for k in _numbers(m.group(1)):
                tags.setdefault(f"({k})", set()).add(path.name)
        for g in _GEN.findall(text):
            tags.setdefault(f"(G{g})", set()).add(path.name)
    return tags


def defined_tags() -> set[str]:
    """Tags docs/MATH.md defines: "(N)", "(a)–(b)" ranges and "(Gk)"."""
    text = MATH.read_text(encoding="utf-8")
    tags = {f"({d})" for d in re.findall(r"\((\d+)\)", text)}
    for a, b in re.findall(r"\((\d+)\)\s*[-–]\s*\((\d+)\)", text):
        tags |= {f"({k})" for k in range(int(a), int(b) + 1)}
    tags |= {f"(G{g})" for g in re.findall(r"\(G([1-9])\)", text)}
    return tags


def test_parser_reads_the_forms_the_code_uses():
    """The tag parser expands ranges and lists (so the next test cannot pass by reading nothing)."""
    assert _numbers("(11)-(14)") == {11, 12, 13, 14}
    assert _numbers("9/10") == {9, 10}
    assert _numbers("(9), (10)") == {9, 10}
    tags = used_tags()
    for tag in ("(2)", "(5)", "(14)", "(15)", "(G1)", "(G2)", "(G3)"):
        assert tag in tags, tag


def test_every_equation_tag_is_in_math_doc():
    """Every "eq. (N)" and "(Gk)" used in the package, the notebooks or README is in docs/MATH.md."""
    missing = {t: sorted(f) for t, f in used_tags().items() if t not in defined_tags()}
    assert not missing, f"tags used but not defined in docs/MATH.md: {missing}"


def test_readme_links_math_doc():
    """README links docs/MATH.md, and nothing points at the old ../shared/MATH.md."""
    assert "](docs/MATH.md)" in (ROOT / "README.md").read_text(encoding="utf-8")
    stale = [p.name for p in _sources() if "shared/MATH" in p.read_text(encoding="utf-8")]
    assert not stale, f"still pointing at shared/MATH.md: {stale}"
