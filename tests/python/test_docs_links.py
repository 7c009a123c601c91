"""Every relative link in README.md and docs/ points at a file of the repository, and every
in-page anchor (`#section`) at a heading of the file it names. Every file of the repository cites
only documents that are in it: a `docs/….md#anchor` resolves, a `docs/paper.md §N` names a numbered
section of docs/paper.md, and no design document from outside the repository is cited."""

import re
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
LINK = re.compile(r"\]\(([^)\s]+)\)")


def _pages():
    return [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]


def _anchors(page):
    """GitHub's heading ids: lower case, punctuation dropped, spaces to hyphens."""
    ids = set()
    in_code = False
    for line in page.read_text(encoding="utf-8").splitlines():
        if line.startswith("```"):
            in_code = not in_code
        if in_code or not line.startswith("#"):
            continue
        text = line.lstrip("#").strip().lower()
        ids.add(re.sub(r"[^\w\- ]", "", text).replace(" ", "-"))
    return ids


def _links(page):
    in_code = False
    for n, line in enumerate(page.read_text(encoding="utf-8").splitlines(), 1):
        if line.startswith("```"):
            in_code = not in_code
        if in_code:
            continue
        for target in LINK.findall(line):
            yield n, target


def test_the_pages_exist():
    assert (ROOT / "README.md").is_file() and len(_pages()) > 3


def test_relative_links_resolve():
    broken = []
    for page in _pages():
        for n, target in _links(page):
            if re.match(r"^[a-z]+:", target):  # http:, https:, mailto:
                continue
            path, _, anchor = target.partition("#")
            dest = (page.parent / path).resolve() if path else page
            where = f"{page.relative_to(ROOT)}:{n}: {target}"
            if not dest.exists():
                broken.append(f"{where} (no such file)")
            elif not dest.is_relative_to(ROOT):
                broken.append(f"{where} (outside the repository)")
            elif anchor and dest.suffix == ".md" and anchor not in _anchors(dest):
                broken.append(f"{where} (no heading #{anchor})")
    assert not broken, "broken links:\n" + "\n".join(broken)


def test_the_checker_sees_a_broken_link(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("# Title\n\nsee [a](missing.md) and [b](#title) and [c](#nope)\n", encoding="utf-8")
    targets = [t for _, t in _links(page)]
    assert targets == ["missing.md", "#title", "#nope"]
    assert _anchors(page) == {"title"}


SOURCE_SUFFIXES = {".rs", ".py", ".sh", ".toml", ".md", ".msg", ".yaml", ".json", ".txt"}
DOC_REF = re.compile(r"\bdocs/([\w./-]+\.md)(?:#([\w-]+))?")
SECTION = re.compile(r"§\s*(\d+(?:\.\d+)*)")
# A design document named in capitals (FOO_NOTES.md, SPEC §2): only README-like files of the repository.
CAPS_DOC = re.compile(r"\b([A-Z][A-Z0-9_]{2,})(?:\.md\b|\s+§)")


def _sources():
    try:
        out = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True).stdout
        files = [ROOT / f for f in out.splitlines()]
    except (OSError, subprocess.CalledProcessError):
        files = [p for p in ROOT.rglob("*") if not {".git", "target", "node_modules"} & set(p.parts)]
    return [f for f in files if f.suffix in SOURCE_SUFFIXES and f.is_file()]


def _sections(page):
    """The section numbers of a page's headings: `## 2. Title` and `### 1.4 Title` give 2 and 1.4."""
    nums = set()
    for line in page.read_text(encoding="utf-8").splitlines():
        m = re.match(r"^#+\s+(\d+(?:\.\d+)*)\.?\s", line)
        if m:
            nums.add(m.group(1))
    return nums


def _citation_problems(path, text, root=ROOT):
    problems = []
    paper = root / "docs" / "paper.md"
    sections = _sections(paper) if paper.exists() else set()
    names = {p.name for p in root.glob("*.md")}
    for n, line in enumerate(text.splitlines(), 1):
        where = f"{path}:{n}"
        for doc, anchor in DOC_REF.findall(line):
            dest = root / "docs" / doc
            if not dest.is_file():
                problems.append(f"{where}: docs/{doc} (no such file)")
            elif anchor and anchor not in _anchors(dest):
                problems.append(f"{where}: docs/{doc}#{anchor} (no such heading)")
        if "paper.md" in line:
            for num in SECTION.findall(line):
                if num not in sections:
                    problems.append(f"{where}: docs/paper.md §{num} (no such section)")
        for name in CAPS_DOC.findall(line):
            if f"{name}.md" not in names:
                problems.append(f"{where}: {name} (a document that is not in the repository)")
    return problems


def test_files_cite_only_documents_in_the_repository():
    problems = []
    for f in _sources():
        if f == Path(__file__).resolve():
            continue
        problems += _citation_problems(f.relative_to(ROOT), f.read_text(encoding="utf-8", errors="replace"))
    assert not problems, "citations of missing documents or sections:\n" + "\n".join(problems)


def test_the_citation_checker_sees_bad_citations(tmp_path):
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "paper.md").write_text("# Paper\n\n## 2. Training\n\n### 1.4 Actor\n", encoding="utf-8")
    (tmp_path / "docs" / "a.md").write_text("# A\n\n## Memory budget\n", encoding="utf-8")
    (tmp_path / "README.md").write_text("# R\n", encoding="utf-8")
    good = "see docs/paper.md §2 and §1.4, docs/a.md#memory-budget, README.md"
    assert _citation_problems(Path("x.rs"), good, tmp_path) == []
    bad = "docs/paper.md §3\ndocs/b.md\ndocs/a.md#nope\nPAPER_SPEC §1.4\nsee DDS_NOTES.md"
    assert [p.split(": ", 1)[1] for p in _citation_problems(Path("x.rs"), bad, tmp_path)] == [
        "docs/paper.md §3 (no such section)",
        "docs/b.md (no such file)",
        "docs/a.md#nope (no such heading)",
        "PAPER_SPEC (a document that is not in the repository)",
        "DDS_NOTES (a document that is not in the repository)",
    ]
