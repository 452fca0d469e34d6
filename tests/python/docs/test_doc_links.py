"""Every relative link in README.md, CHANGELOG.md and docs/ resolves: the file exists, and a
`#fragment` names a heading of the target page (GitHub's anchors: lower case, punctuation
dropped, spaces to hyphens, `-1`, `-2` for repeats). Links inside code blocks and spans are not
links; http(s) and mailto addresses are not checked (the tests run offline)."""
import re
from functools import cache
from pathlib import Path

import pytest

from conftest import REPO

PAGES = sorted([REPO / "README.md", REPO / "CHANGELOG.md", *(REPO / "docs").rglob("*.md")])
LINK = re.compile(r"(?<!!)\[(?:[^\]\\]|\\.)*\]\(([^()\s]+)(?:\s+\"[^\"]*\")?\)|!\[[^\]]*\]\(([^()\s]+)\)")
FENCE = re.compile(r"^(```|~~~).*?^\1[ \t]*$", re.S | re.M)
CODE_SPAN = re.compile(r"(`+)(?:(?!\1).)+?\1", re.S)


def _blank(m: re.Match) -> str:
    return re.sub(r"[^\n]", " ", m.group(0))


def prose(text: str, spans: bool = True) -> str:
    """The page without fenced code blocks and (`spans`) code spans, newlines kept."""
    text = FENCE.sub(_blank, text)
    return CODE_SPAN.sub(_blank, text) if spans else text


def slug(heading: str) -> str:
    text = re.sub(r"`([^`]*)`", r"\1", heading.strip())
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", text)          # a link's text only
    text = re.sub(r"[^\w\- ]", "", text.lower(), flags=re.U)
    return text.replace(" ", "-")


@cache
def anchors(page: Path) -> frozenset[str]:
    seen: dict[str, int] = {}
    out = set()
    for line in prose(page.read_text(), spans=False).splitlines():
        m = re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line)
        if not m:
            continue
        base = slug(m.group(1))
        n = seen.get(base, 0)
        seen[base] = n + 1
        out.add(base if n == 0 else f"{base}-{n}")
    out.update(re.findall(r'<a\s+(?:name|id)="([^"]+)"', page.read_text()))
    return frozenset(out)


def links(page: Path):
    for lineno, line in enumerate(prose(page.read_text()).splitlines(), 1):
        for m in LINK.finditer(line):
            yield lineno, m.group(1) or m.group(2)


def broken(page: Path) -> list[str]:
    bad = []
    for lineno, target in links(page):
        if re.match(r"^[a-z][a-z0-9+.-]*:", target, re.I):     # http:, https:, mailto:
            continue
        path, _, fragment = target.partition("#")
        dest = (page.parent / path).resolve() if path else page
        where = f"{page.relative_to(REPO)}:{lineno}: ({target})"
        if not dest.exists():
            bad.append(f"{where}: no such file")
        elif fragment and dest.suffix == ".md" and fragment not in anchors(dest):
            bad.append(f"{where}: no heading with anchor #{fragment}")
    return bad


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(REPO)))
def test_relative_links_resolve(page):
    assert broken(page) == []


def test_the_checker_finds_broken_links(tmp_path, monkeypatch):
    monkeypatch.setattr("test_doc_links.REPO", tmp_path)
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "b.md").write_text("# B page\n\n## Two words, (here)+\n")
    page = tmp_path / "docs" / "a.md"
    page.write_text("# A\n[ok](b.md) [ok](b.md#two-words-here) [ok](#a) [ok](https://x.org/y)\n"
                    "`[not a link](nowhere.md)`\n```\n[nor](this.md)\n```\n"
                    "[gone](c.md) [bad anchor](b.md#three) [bad local](#b)\n")
    assert [b.split(": ", 1)[1] for b in broken(page)] == [
        "(c.md): no such file", "(b.md#three): no heading with anchor #three",
        "(#b): no heading with anchor #b"]
