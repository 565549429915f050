"""Every relative link in the README and docs/ leads to a file that exists, and an anchor to a
heading that exists: pages moved between guides/, reference/ and design/ leave no dead link."""
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PAGES = [ROOT / "README.md"] + sorted((ROOT / "docs").rglob("*.md"))
LINK = re.compile(r"(?<!!)\[[^\]]*\]\(([^)\s]+)\)")
CODE = re.compile(r"```.*?```|`[^`\n]*`", re.S)
FENCED = re.compile(r"```.*?```", re.S)


def anchors(page: Path) -> set:
    """GitHub's anchors of a page's headings: lower case, punctuation dropped (a code span's
    text kept, its backticks dropped), spaces to -."""
    found = set()
    for heading in re.findall(r"^#+\s+(.*)$", FENCED.sub("", page.read_text(encoding="utf-8")), re.M):
        slug = re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")
        found.add(slug)
    return found


def links(page: Path):
    return LINK.findall(CODE.sub("", page.read_text(encoding="utf-8")))


def test_every_relative_link_leads_somewhere():
    dead = []
    for page in PAGES:
        for target in links(page):
            if re.match(r"[a-z]+:", target):          # http:, https:, mailto:
                continue
            path, _, anchor = target.partition("#")
            goal = (page.parent / path).resolve() if path else page
            if not goal.exists():
                dead.append(f"{page.relative_to(ROOT)}: {target} (no such file)")
            elif anchor and goal.suffix == ".md" and anchor not in anchors(goal):
                dead.append(f"{page.relative_to(ROOT)}: {target} (no such heading)")
    assert not dead, "\n".join(dead)


def test_the_link_finder_sees_links_and_skips_code(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("# A title\n[one](other.md#a-title) `[not](x.md)` ![pic](p.png)\n"
                    "```\n[nor](y.md)\n# not a heading\n```\n## Tables (`bench_speed.py`)\n",
                    encoding="utf-8")
    assert links(page) == ["other.md#a-title"]
    assert anchors(page) == {"a-title", "tables-bench_speedpy"}
