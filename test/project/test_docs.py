"""The docs run as a reader follows them: every ```bash and ```python block of README.md, then
of every page in the order docs/README.md links them (then any page it does not link), one
after another in ONE fresh copy of the checkout, so that a page that collides with an
earlier one (an output name taken, a file it expects gone) fails here as it would for the
reader. They cannot go stale.

The copy is what a user has after `git clone` (the files git tracks, and new ones not yet
ignored), in a temporary directory: blocks that read `config/...` or call `scripts/...` find
them, and nothing a block writes ever lands in the checkout. Blocks run with the venv's bin
first on PATH, a temporary HOME and TMPDIR, a DDS domain of their own on loopback (ROS 2
left out, so nodes run on the dds transport), no network (proxies point nowhere, pip may not
reach an index) and the machine's compiled-kernel cache (ARM_SIM_CACHE, as the rest of the
suite uses it). A block immediately preceded by `<!-- not run: REASON -->` is skipped;
NOT_RUN_BLOCKS lists every such block with its reason, and the test fails when a skip has no
reason. Output meant for the reader belongs in ```text blocks, which are not run.

Each page writes under names of its own (`runs/<page>_...`; the README's are plain):
test_no_two_pages_name_the_same_output checks every block, run or not.
"""
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from arm_sim_ros.physics.compiled.build import cache_dir

ROOT = Path(__file__).resolve().parents[2]
INDEX = ROOT / "docs" / "README.md"
FENCE = re.compile(r"(?P<before>(?:[^\n]*\n){0,1})```(?P<lang>bash|python)\n(?P<code>.*?)\n```",
                   re.S)
NOT_RUN = re.compile(r"<!--\s*not run:\s*(?P<reason>.*?)\s*-->\s*$")
LINK = re.compile(r"\]\((?P<target>[^)#\s]+\.md)(?:#[^)\s]*)?\)")
OUTPUT = re.compile(r"\bruns/(?P<name>[\w.-]+)")
BLOCK_SECONDS = 120        # a hard stop; blocks are meant to take a few seconds
DOMAIN_ID = "204"          # the blocks' nodes talk only among themselves


def reading_order() -> list:
    """README.md, docs/README.md, the pages it links in the order it links them, then any
    page under docs/ it does not link (sorted)."""
    linked = []
    for match in LINK.finditer(INDEX.read_text(encoding="utf-8")):
        page = (INDEX.parent / match["target"]).resolve()
        if page.is_file() and INDEX.parent in page.parents and page not in linked:
            linked.append(page)
    rest = sorted(set(INDEX.parent.rglob("*.md")) - set(linked) - {INDEX})
    return [ROOT / "README.md", INDEX, *linked, *rest]


DOCS = reading_order()


def blocks(path: Path) -> list:
    """[(line, language, code, reason it is not run or None)] of a Markdown file."""
    text = path.read_text(encoding="utf-8")
    found = []
    for match in FENCE.finditer(text):
        line = text.count("\n", 0, match.start("lang")) + 1
        marker = NOT_RUN.search(match["before"].strip("\n") or "")
        found.append((line, match["lang"], match["code"],
                      marker["reason"] if marker else None))
    return found


NOT_RUN_BLOCKS = [(path.relative_to(ROOT).as_posix(), line, reason)
                  for path in DOCS for line, _, _, reason in blocks(path) if reason is not None]


def user_copy(target: Path) -> Path:
    """The checkout as a clone has it: the files git tracks (as they are in the work tree)
    and new ones it does not ignore, copied into `target`."""
    listed = subprocess.run(["git", "ls-files", "-z", "--cached", "--others",
                             "--exclude-standard"], cwd=ROOT, capture_output=True, check=True)
    for name in sorted(set(listed.stdout.decode().split("\0")) - {""}):
        source = ROOT / name
        if source.is_file():                      # a file deleted in the work tree: gone
            (target / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(source, target / name)
    return target


def environment(scratch: Path) -> dict:
    # ROS 2 left out even where it is sourced: the blocks' nodes run on the dds transport
    env = {k: v for k, v in os.environ.items()
           if not k.startswith(("ROS_", "RMW_", "CYCLONEDDS")) and k != "PYTHONPATH"}
    nowhere = "http://127.0.0.1:9"          # no network: anything that tries fails at once
    for name in ("home", "tmp"):
        (scratch / name).mkdir()
    return env | {
        "PATH": f"{Path(sys.executable).parent}{os.pathsep}{env['PATH']}",
        "HOME": str(scratch / "home"), "TMPDIR": str(scratch / "tmp"),
        # the machine's compiled kernels, as a user's runs find them (a new HOME would
        # compile every scene again, in every file)
        "ARM_SIM_CACHE": str(cache_dir()), "ROS_DOMAIN_ID": DOMAIN_ID,
        "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
        "http_proxy": nowhere, "https_proxy": nowhere, "HTTP_PROXY": nowhere,
        "HTTPS_PROXY": nowhere, "PIP_NO_INDEX": "1", "MPLBACKEND": "Agg",
    }


@pytest.fixture(scope="module")
def reader(tmp_path_factory):
    """(the reader's copy of the checkout, the blocks' environment), one for every page."""
    try:
        subprocess.run(["git", "rev-parse"], cwd=ROOT, capture_output=True, check=True)
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout: the reader's copy is made from `git ls-files`")
    scratch = tmp_path_factory.mktemp("reader")
    return user_copy(scratch / "arm_sim_ros"), environment(scratch)


def run_block(language: str, code: str, cwd: Path, env: dict) -> subprocess.CompletedProcess:
    command = (["bash", "-euo", "pipefail", "-c", code] if language == "bash"
               else [sys.executable, "-c", code])
    return subprocess.run(command, cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=BLOCK_SECONDS)


@pytest.mark.parametrize("path", DOCS, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_every_block_of_the_file_runs(path, reader):
    """In reading order, each page after the ones before it, all in the one copy."""
    copy, env = reader
    for line, language, code, reason in blocks(path):
        if reason is not None:
            continue
        done = run_block(language, code, copy, env)
        assert done.returncode == 0, (
            f"{path.relative_to(ROOT)}:{line} ({language}) exited {done.returncode}\n"
            f"--- stdout\n{done.stdout[-3000:]}\n--- stderr\n{done.stderr[-3000:]}")
        # numpy 2's repr of a scalar is no number a reader expects (the README's bag snippet
        # printed [np.float64(-2.46...), ...])
        assert "np.float64(" not in done.stdout, f"{path.relative_to(ROOT)}:{line}: {done.stdout}"


def test_the_reading_order_is_the_readme_then_the_index_in_its_order():
    order = [p.relative_to(ROOT).as_posix() for p in DOCS]
    assert order[:3] == ["README.md", "docs/README.md", "docs/guides/effects.md"]
    linked = [p.relative_to(ROOT).as_posix() for p in DOCS[2:]]
    assert linked.index("docs/guides/recordings.md") < linked.index("docs/guides/fit.md")
    assert sorted(order) == sorted(["README.md"] + [p.relative_to(ROOT).as_posix()
                                                    for p in (ROOT / "docs").rglob("*.md")])


def test_every_page_under_docs_is_linked_from_the_index():
    unlinked = [p.relative_to(ROOT).as_posix() for p in DOCS[2:]
                if p not in [(INDEX.parent / m["target"]).resolve()
                             for m in LINK.finditer(INDEX.read_text(encoding="utf-8"))]]
    assert unlinked == [], "docs/README.md links every page a reader follows"


def test_the_readmes_guide_table_is_the_indexs():
    """README.md's table of guides (its section "More") lists those of docs/README.md, in
    the same order: reliability.md was missing from it."""
    def guides(page: Path, text: str) -> list:
        return [(page.parent / m["target"]).resolve() for m in LINK.finditer(text)
                if "guides/" in m["target"]]

    more = (ROOT / "README.md").read_text(encoding="utf-8").split("\n## More\n", 1)[1]
    index = INDEX.read_text(encoding="utf-8")
    assert guides(ROOT / "README.md", more.split("\n## ", 1)[0]) == guides(INDEX, index.split(
        "## Guides", 1)[1].split("\n## ", 1)[0])


def outputs(path: Path) -> set:
    """The names under runs/ a page's blocks (run or not) mention."""
    return {m["name"].rstrip(".") for _, _, code, _ in blocks(path)
            for m in OUTPUT.finditer(code)}


def test_no_two_pages_name_the_same_output():
    """A page that reused another's runs/damped met `exists already` when read after it."""
    owner = {}
    for path in DOCS:
        for name in sorted(outputs(path)):
            page = owner.setdefault(name, path.relative_to(ROOT).as_posix())
            assert page == path.relative_to(ROOT).as_posix(), (
                f"runs/{name} is written by {page} and by {path.relative_to(ROOT)}: a page "
                "writes under names of its own (runs/<page>_...)")


def test_each_guide_writes_under_its_own_prefix():
    for path in DOCS[2:]:
        foreign = sorted(name for name in outputs(path) if not name.startswith(f"{path.stem}_"))
        assert foreign == [], f"{path.relative_to(ROOT)}: runs/{foreign} lack '{path.stem}_'"


def test_every_skipped_block_says_why():
    """The curated list of blocks that are not run, each with its reason."""
    for where, line, reason in NOT_RUN_BLOCKS:
        assert len(reason) >= 10, f"{where}:{line}: '<!-- not run: ... -->' needs a reason"
    print("\n".join(f"not run: {where}:{line}: {reason}" for where, line, reason in NOT_RUN_BLOCKS))


def test_the_docs_have_blocks_that_run_and_the_readme_is_short():
    runnable = [b for path in DOCS for b in blocks(path) if b[3] is None]
    assert len(runnable) >= 20
    assert len((ROOT / "README.md").read_text(encoding="utf-8").splitlines()) <= 250


def test_a_count_the_docs_state_is_the_codes():
    """"18 presets" stayed in five places after there were 20: a count is the code's, or
    left to a command that prints it (`arm-sim scenes`) or the generated reference."""
    from arm_sim_ros.physics.scene import preset_names

    for path in DOCS:
        for count in re.findall(r"\b(\d+) (?:presets|preset scenes)\b",
                                path.read_text(encoding="utf-8")):
            assert int(count) == len(preset_names()), f"{path.relative_to(ROOT)}: {count}"


def test_every_picture_the_docs_show_exists():
    for path in DOCS:
        for target in re.findall(r"!\[[^\]]*\]\(([^)\s]+)\)", path.read_text(encoding="utf-8")):
            assert (path.parent / target).is_file(), f"{path.relative_to(ROOT)}: {target}"


def test_a_skip_marker_is_recognised_only_right_before_its_block(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("<!-- not run: needs ROS 2 sourced -->\n```bash\nros2 topic list\n```\n\n"
                    "<!-- not run: far away -->\n\ntext\n```python\nprint(1)\n```\n")
    assert [(lang, reason) for _, lang, _, reason in blocks(page)] == [
        ("bash", "needs ROS 2 sourced"), ("python", None)]


def test_the_readers_copy_is_what_git_tracks_and_lies_outside_the_checkout(tmp_path):
    copy = user_copy(tmp_path / "copy")
    tracked = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True,
                             check=True).stdout.split()
    assert all((copy / name).is_file() for name in tracked if (ROOT / name).is_file())
    assert not (copy / ".venv").exists() and not (copy / ".git").exists()
    assert ROOT not in copy.resolve().parents


def test_every_test_the_reliability_guide_names_exists():
    """docs/guides/reliability.md gives each promise the test that holds it (a file, then
    `::name` of a test in the file named last): each is there, so a renamed or removed
    test shows here."""
    text = (ROOT / "docs" / "guides" / "reliability.md").read_text()
    named, last = 0, None
    for found in re.finditer(r"`(test/[\w/]+\.py|test_\w+\.py)?(?:::(\w+))?`", text):
        path, name = found.groups()
        if path:
            last = ROOT / path if path.startswith("test/") else next((ROOT / "test").rglob(path))
            assert last.exists(), path
        if name:
            assert f"def {name}(" in last.read_text(), f"{last.name}::{name}"
            named += 1
    assert named >= 20
