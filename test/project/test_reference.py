"""docs/reference/ is made from the code (arm_sim_ros/tools/reference.py): a page that differs
from what the code declares today fails here, so the reference cannot go stale."""
from pathlib import Path

from arm_sim_ros.tools.reference import OFFLINE_ONLY, pages, scene_keys

FOLDER = Path(__file__).resolve().parents[2] / "docs" / "reference"


def test_every_reference_page_is_what_the_code_declares():
    made = pages()
    assert sorted(p.name for p in FOLDER.glob("*.md")) == sorted(made)
    stale = [name for name, text in made.items()
             if (FOLDER / name).read_text(encoding="utf-8") != text]
    assert not stale, f"docs/reference/{stale} are stale: run scripts/reference"


def test_every_scene_key_has_a_meaning_and_the_offline_ones_are_only_those_the_node_lacks():
    keys = {row[0].strip("`") for row in scene_keys()}
    assert set(OFFLINE_ONLY) <= keys
    assert all(row[3] for row in scene_keys())
