"""The documentation's links hold (issue 60): every relative link of the README, the changelog and docs/ leads to a
file that is there and, with a ``#fragment``, to a heading or an ``<a id>`` of it; code, tests and research cite a
section of a doc by an explicit anchor (``docs/investigations/sfm.md#mapping-past-1000``: an ``<a id>`` before the
heading, which stays when the title changes), and every such anchor is there."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", ROOT / "CHANGELOG.md", *sorted((ROOT / "docs").rglob("*.md"))]


def _slug(title: str) -> str:
    """GitHub's id of a heading: lower case, punctuation dropped (``-`` and ``_`` kept), spaces as ``-``."""
    return re.sub(r"[^\w\- ]", "", title.strip().lower()).replace(" ", "-")


def _anchors(md: Path) -> tuple[set[str], set[str]]:
    """(the ids of its headings, its explicit ``<a id>``s); headings inside fenced code are none."""
    seen: dict[str, int] = {}
    headings: set[str] = set()
    ids: set[str] = set()
    fenced = False
    for line in md.read_text().splitlines():
        if line.lstrip().startswith("```"):
            fenced = not fenced
            continue
        if fenced:
            continue
        ids.update(re.findall(r'<a id="([^"]+)"', line))
        m = re.match(r"#{1,6} (.*)", line)
        if m:
            s = _slug(m.group(1))
            headings.add(s if s not in seen else f"{s}-{seen[s]}")      # a second "Speed": speed-1
            seen[s] = seen.get(s, 0) + 1
    return headings, ids


PENDING: set[str] = set()
"""Links to a section being written: remove each once its section is there."""


def test_every_link_of_the_docs_leads_somewhere():
    bad = []
    for md in DOCS:
        text = re.sub(r"```.*?```", "", md.read_text(), flags=re.S)
        for target in re.findall(r"\]\(([^)\s]+)\)", text):
            if re.match(r"[a-z]+:", target):
                continue
            path, _, frag = target.partition("#")
            dest = (md.parent / path).resolve() if path else md
            if not dest.exists():
                bad.append(f"{md.relative_to(ROOT)}: {target} (no such file)")
            elif frag and dest.suffix == ".md" and frag not in set.union(*_anchors(dest)) and target not in PENDING:
                bad.append(f"{md.relative_to(ROOT)}: {target} (no such section)")
    assert not bad, "\n".join(bad)


def test_code_cites_a_doc_by_an_anchor_that_is_there():
    bad, n = [], 0
    for py in sorted(p for d in ("curate", "research", "tests", "scripts") for p in (ROOT / d).rglob("*.py")):
        for doc, frag in re.findall(r"(docs/[\w/-]+\.md)#([\w-]+)", py.read_text()):
            n += 1
            if not (ROOT / doc).is_file():
                bad.append(f"{py.relative_to(ROOT)}: {doc} (no such file)")
            elif frag not in _anchors(ROOT / doc)[1]:
                bad.append(f"{py.relative_to(ROOT)}: {doc}#{frag} (no <a id=\"{frag}\"> there)")
    assert not bad, "\n".join(bad)
    assert n >= 10                                  # the check sees them
