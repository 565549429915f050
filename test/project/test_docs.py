"""The docs run: every ```bash and ```python block in README.md and docs/*.md is executed, so
they cannot go stale.

Blocks run in the order they appear, one file after another, from the repository root, with
the venv's bin first on PATH, a temporary HOME, a DDS domain of their own on loopback (ROS 2
left out, so nodes run on the dds transport), and no network (proxies point nowhere, pip may not reach an index). A block immediately preceded by
`<!-- not run: REASON -->` is skipped; NOT_RUN lists every such block with its reason, and
the test fails when a skip has no reason. What the blocks write (runs/ and the like, all in
.gitignore) is removed after each file, and a runs/ that was there before is put back.
Output meant for the reader belongs in ```text blocks, which are not run.
"""
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DOCS = [ROOT / "README.md"] + sorted((ROOT / "docs").rglob("*.md"))
FENCE = re.compile(r"(?P<before>(?:[^\n]*\n){0,1})```(?P<lang>bash|python)\n(?P<code>.*?)\n```",
                   re.S)
NOT_RUN = re.compile(r"<!--\s*not run:\s*(?P<reason>.*?)\s*-->\s*$")
BLOCK_SECONDS = 60         # a hard stop; blocks are meant to take a few seconds
DOMAIN_ID = "204"          # the blocks' nodes talk only among themselves
SCRATCH = ("runs", "arm_sim.rrd", "run.csv", "accuracy.json")   # what blocks may write


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


def environment(home: Path) -> dict:
    # ROS 2 left out even where it is sourced: the blocks' nodes run on the dds transport
    env = {k: v for k, v in os.environ.items()
           if not k.startswith(("ROS_", "RMW_", "CYCLONEDDS")) and k != "PYTHONPATH"}
    nowhere = "http://127.0.0.1:9"          # no network: anything that tries fails at once
    return env | {
        "PATH": f"{Path(sys.executable).parent}{os.pathsep}{env['PATH']}",
        "HOME": str(home), "ROS_DOMAIN_ID": DOMAIN_ID,
        # the machine's compiled kernels, as a user's runs find them (a new HOME would
        # compile every scene again, in every file)
        "ARM_SIM_CACHE": env.get("ARM_SIM_CACHE") or str(Path.home() / ".cache/arm_sim_ros"),
        "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
        "http_proxy": nowhere, "https_proxy": nowhere, "HTTP_PROXY": nowhere,
        "HTTPS_PROXY": nowhere, "PIP_NO_INDEX": "1", "MPLBACKEND": "Agg",
    }


def run_block(language: str, code: str, env: dict) -> subprocess.CompletedProcess:
    command = (["bash", "-euo", "pipefail", "-c", code] if language == "bash"
               else [sys.executable, "-c", code])
    return subprocess.run(command, cwd=ROOT, env=env, capture_output=True, text=True,
                          timeout=BLOCK_SECONDS)


@pytest.fixture
def scratch(tmp_path):
    """Put aside what the blocks would collide with; remove what they wrote; restore."""
    aside = tmp_path / "aside"
    aside.mkdir()
    for name in SCRATCH:
        if (ROOT / name).exists():
            shutil.move(str(ROOT / name), aside / name)
    try:
        yield
    finally:
        for name in SCRATCH:
            target = ROOT / name
            if target.is_dir() and not target.is_symlink():
                shutil.rmtree(target)
            elif target.exists() or target.is_symlink():
                target.unlink()
            if (aside / name).exists():
                shutil.move(str(aside / name), target)


@pytest.mark.parametrize("path", DOCS, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_every_block_of_the_file_runs(path, tmp_path, scratch):
    home = tmp_path / "home"
    home.mkdir()
    env = environment(home)
    for line, language, code, reason in blocks(path):
        if reason is not None:
            continue
        done = run_block(language, code, env)
        assert done.returncode == 0, (
            f"{path.relative_to(ROOT)}:{line} ({language}) exited {done.returncode}\n"
            f"--- stdout\n{done.stdout[-3000:]}\n--- stderr\n{done.stderr[-3000:]}")


def test_every_skipped_block_says_why():
    """The curated list of blocks that are not run, each with its reason."""
    for where, line, reason in NOT_RUN_BLOCKS:
        assert len(reason) >= 10, f"{where}:{line}: '<!-- not run: ... -->' needs a reason"
    print("\n".join(f"not run: {where}:{line}: {reason}" for where, line, reason in NOT_RUN_BLOCKS))


def test_the_docs_have_blocks_that_run_and_the_readme_is_short():
    runnable = [b for path in DOCS for b in blocks(path) if b[3] is None]
    assert len(runnable) >= 20
    assert len((ROOT / "README.md").read_text(encoding="utf-8").splitlines()) <= 250


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
