"""One rule for degrees: every key whose unit is an angle (rad, or rad per count) takes
`90deg` wherever a value is given (--set, a scene file, the node's parameters:
test/node/test_ros_args.py), and every other key refuses `deg`, naming the keys that take it.
`sensors.position_resolution` (rad per count) refused `deg`, and the node took it nowhere."""
from math import radians

import pytest

from arm_sim_ros.physics.angles import ANGLE_KEYS
from arm_sim_ros.physics.scene import MAPPINGS, SceneError, load_scene, scene_from_file


def test_the_angle_keys_are_every_key_in_rad_and_only_those():
    assert ANGLE_KEYS == ("initial_positions", "joint_limits.lower", "joint_limits.upper",
                          "sensors.position_resolution", "sensors.position_noise",
                          "sensors.position_offset", "springs.rest_positions")
    assert all(p.unit not in ("rad", "rad per count") for effect, mapping in MAPPINGS.items()
               for p in mapping.parameters if f"{effect}.{p.name}" not in ANGLE_KEYS)


@pytest.mark.parametrize("assignment, key, expected", [
    ("initial_positions=90deg,-30deg", "initial_positions", (radians(90), radians(-30))),
    ("sensors.position_resolution=0.1deg,0.1deg", "sensors", (radians(0.1), radians(0.1))),
    ("sensors.position_offset=1deg,0", "sensors", (radians(1), 0.0)),
])
def test_set_takes_degrees_on_every_angle_key(assignment, key, expected):
    scene = load_scene("release").with_text_overrides([assignment])
    value = getattr(scene, key)
    got = value["position_resolution" if "resolution" in assignment else "position_offset"] \
        if key == "sensors" else value
    assert got == pytest.approx(expected, rel=1e-15)


def test_a_scene_file_takes_degrees_too(tmp_path):
    path = tmp_path / "arm.yaml"
    path.write_text("initial_positions: [90deg, 0]\nsprings:\n  stiffness: [20, 5]\n"
                    "  rest_positions: [30deg, -30deg]\n")
    scene = scene_from_file(path, "arm")
    assert scene.initial_positions == pytest.approx((radians(90), 0.0))
    assert scene.springs["rest_positions"] == pytest.approx((radians(30), radians(-30)))


@pytest.mark.parametrize("assignment", ["damping=5deg", "gravity=9.81deg",
                                        "springs.stiffness=20deg,5"])
def test_a_key_that_is_no_angle_refuses_deg_and_names_those_that_take_it(assignment):
    with pytest.raises(SceneError) as refused:
        load_scene("release").with_text_overrides([assignment])
    assert "only angles take deg, the keys in rad: initial_positions, " in str(refused.value)
    assert "sensors.position_resolution" in str(refused.value)
