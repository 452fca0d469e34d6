"""Docs and source comments describe what is: none cites an issue or a session of the work, or
a figure it replaced ("was 152", "(was ..."). The history of releases is CHANGELOG.md's.

The pattern, case-insensitive, is HISTORY below; it runs over README.md, CHANGELOG.md, docs/,
and the text files under host/, firmware/, tools/, cmake/, examples/ and tests/ (this file
excepted), plus CMakeLists.txt."""
import re
from pathlib import Path

import pytest

from conftest import REPO

HISTORY = re.compile(r"issue [0-9]+|session [0-9]+|\(was |was [0-9]", re.I)
TREES = ("docs", "host", "firmware", "tools", "cmake", "examples", "tests")
FILES = ("README.md", "CHANGELOG.md", "CMakeLists.txt")
SUFFIXES = {".md", ".py", ".c", ".h", ".in", ".cmake", ".txt", ".sh", ".toml", ".cfg", ".json"}
SKIP_DIRS = {"build", "__pycache__", ".venv", "_firmware"}


def scanned(repo: Path) -> list[Path]:
    paths = [repo / f for f in FILES if (repo / f).is_file()]
    for tree in TREES:
        for p in sorted((repo / tree).rglob("*")):
            rel = p.relative_to(repo).parts
            if (p.is_file() and p.suffix in SUFFIXES and not SKIP_DIRS.intersection(rel)
                    and not any(part.endswith(".egg-info") for part in rel)
                    and p.resolve() != Path(__file__).resolve()):
                paths.append(p)
    return paths


def history_lines(repo: Path) -> list[str]:
    hits = []
    for p in scanned(repo):
        try:
            text = p.read_text()
        except UnicodeDecodeError:
            continue
        for n, line in enumerate(text.splitlines(), 1):
            if HISTORY.search(line):
                hits.append(f"{p.relative_to(repo)}:{n}: {line.strip()[:120]}")
    return hits


def test_docs_and_comments_cite_no_issue_session_or_old_figure():
    assert history_lines(REPO) == []


@pytest.mark.parametrize("planted", [
    "/* the compressed format of issue 13 */", "# see Issue 7, item 2",
    "Measured in session 18.", "188 B (Q15, was 152)", "it was 2-34 % before"])
def test_a_planted_line_is_found(tmp_path, planted):
    for tree in ("docs", "firmware/src", "tests/python"):
        (tmp_path / tree).mkdir(parents=True)
    (tmp_path / "README.md").write_text("# stospline\n\nWhat is.\n")
    (tmp_path / "firmware/src/a.c").write_text("/* clean */\nint x;\n")
    assert history_lines(tmp_path) == []
    (tmp_path / "firmware/src/a.c").write_text(f"int x;\n{planted}\n")
    assert history_lines(tmp_path) == [f"firmware/src/a.c:2: {planted}"]
