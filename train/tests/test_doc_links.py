"""The links in the README and the documents resolve: every relative link or image names a file or
folder of the checkout, and every #anchor names a heading of the file it points into, by GitHub's
rule for heading anchors."""

from __future__ import annotations

import re
from pathlib import Path

from conftest import ROOT

# Inline links and images, [text](target) and ![alt](target), the target up to an optional title.
LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\[\]]*\])*\]\(\s*<?([^)\s>]*)>?(?:\s+\"[^\"]*\")?\s*\)")
CODE_SPAN = re.compile(r"(`+)(?:(?!\1).)+?\1")
FENCE = re.compile(r"^\s*(```|~~~)")
HEADING = re.compile(r"^\s{0,3}(#{1,6})\s+(.*?)\s*#*\s*$")


def documents() -> list[Path]:
    """The README, docs/, results/README.md and the default model's card."""
    docs = [ROOT / "README.md", ROOT / "results" / "README.md", ROOT / "models" / "README.md"]
    return docs + sorted((ROOT / "docs").glob("*.md"))


def prose_lines(text: str, code_spans: bool = False) -> list[tuple[int, str]]:
    """The lines outside fenced code blocks, numbered from 1, with code spans removed unless asked."""
    lines, fenced = [], None
    for number, line in enumerate(text.splitlines(), start=1):
        fence = FENCE.match(line)
        if fence:
            if fenced is None:
                fenced = fence.group(1)
            elif fence.group(1) == fenced:
                fenced = None
            continue
        if fenced is None:
            lines.append((number, line if code_spans else CODE_SPAN.sub("", line)))
    return lines


def slug(heading: str) -> str:
    """GitHub's anchor for a heading: its text without markup, lower-cased, punctuation but
    hyphens and spaces dropped, spaces turned to hyphens."""
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", heading)  # a link in a heading keeps its text
    text = re.sub(r"<[^>]+>", "", text).lower()
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


def anchors(path: Path) -> set[str]:
    """Every heading anchor of a markdown file; a repeated heading gets -1, -2, ... as on GitHub."""
    seen: dict[str, int] = {}
    found = set()
    for _, line in prose_lines(path.read_text(encoding="utf-8"), code_spans=True):
        heading = HEADING.match(line)
        if not heading:
            continue
        base = slug(heading.group(2).replace("`", ""))
        count = seen.get(base, 0)
        seen[base] = count + 1
        found.add(base if count == 0 else f"{base}-{count}")
    return found


def broken_links(doc: Path) -> list[str]:
    """`file:line: target (why)` for every link of doc that does not resolve."""
    broken = []
    for number, line in prose_lines(doc.read_text(encoding="utf-8")):
        for match in LINK.finditer(line):
            target = match.group(1)
            if not target or re.match(r"^(https?:|mailto:)", target, re.IGNORECASE):
                continue
            where = f"{doc.relative_to(ROOT)}:{number}: {target}"
            path_part, _, anchor = target.partition("#")
            linked = (doc.parent / path_part).resolve() if path_part else doc
            if not linked.exists():
                broken.append(f"{where} (no such file)")
            elif not linked.is_relative_to(ROOT):
                broken.append(f"{where} (outside the checkout)")
            elif anchor and linked.suffix == ".md" and anchor not in anchors(linked):
                broken.append(f"{where} (no heading #{anchor} in {linked.relative_to(ROOT)})")
    return broken


def test_the_anchor_rule_is_githubs() -> None:
    assert slug("Live: virtual camera and OBS") == "live-virtual-camera-and-obs"
    assert slug("The crop (version 2)") == "the-crop-version-2"
    assert slug("The source light's fine shading") == "the-source-lights-fine-shading"
    assert slug("The saved network (network.pt)") == "the-saved-network-networkpt"
    assert slug("Beyond the paper: the shipped default's two extra losses") == (
        "beyond-the-paper-the-shipped-defaults-two-extra-losses"
    )


def test_every_link_in_the_readme_and_docs_resolves() -> None:
    docs = documents()
    assert ROOT / "README.md" in docs and len(docs) > 3, docs
    broken = [line for doc in docs for line in broken_links(doc)]
    assert not broken, "broken links:\n" + "\n".join(broken)
