"""Batch rollouts equal the single-arm simulator, arm by arm, and refuse what it refuses."""
import numpy as np
import pytest

from arm_sim_ros.physics import batch as batch_module
from arm_sim_ros.tools import cli
from arm_sim_ros.physics.batch import Batch
from arm_sim_ros.physics.scene import SceneError, load_scene, preset_names
from arm_sim_ros.physics.simulator import Simulator
from physics.test_effort_events import mode_free

RNG = np.random.default_rng(7)


def single(scene, steps, command=None):
    """q1, q2, qd1, qd2, work, dissipated of one arm (0 for an absent channel), stepped as
    a batch steps it: the stability plan's sub-steps, no tolerance's (tools/batch.py)."""
    sim = Simulator(scene.replace(tolerance=0.0))
    if command is not None:
        sim.set_command(*command)
    for _ in range(steps):
        sim.step()
    books = dict(zip(sim.channels, sim.state[4:]))
    return np.array([*sim.state[:4], books.get("work", 0.0), books.get("dissipated", 0.0)])


def assert_batch_equals_single(batch, scenes, steps, commands=None):
    for i, scene in enumerate(scenes):
        expected = single(scene, steps, None if commands is None else commands[i])
        got = np.array([*(a[i] for a in batch.state[:4]), batch.channel("work")[i],
                        batch.channel("dissipated")[i]])
        assert np.max(np.abs(got - expected)) <= 1e-12, (i, got, expected)


@pytest.mark.parametrize("name", ["release", "damped_release", "shoulder_torque_no_gravity",
                                  "moving_gravity_compensation", "moving_frozen_gravity"])
def test_batch_equals_single_arm_rk4_for_different_initial_states(name):
    scene = load_scene(name)
    q = np.asarray(scene.initial_positions) + RNG.uniform(-1, 1, (5, 2))
    qd = np.asarray(scene.initial_velocities) + RNG.uniform(-1, 1, (5, 2))
    b = Batch(scene, q, qd)
    b.run(50)
    assert b.time == pytest.approx(0.5)
    scenes = [scene.replace(initial_positions=tuple(q[i]), initial_velocities=tuple(qd[i]))
              for i in range(5)]
    assert_batch_equals_single(b, scenes, 50)


def test_batch_equals_single_arm_rk4_for_different_parameters():
    scene = load_scene("release")
    n = 4
    params = {"gravity": RNG.uniform(0, 12, n), "damping": np.array([0.0, 0.1, 0.5, 0.0]),
              "link_lengths": RNG.uniform(0.5, 1.5, (n, 2)),
              "link_masses": RNG.uniform(0.5, 2.0, (n, 2)),
              "com_distances": RNG.uniform(0.2, 0.8, (n, 2)),
              "com_inertias": RNG.uniform(0.01, 0.2, (n, 2))}
    b = Batch(scene, count=n, **params)
    b.run(40)
    scenes = [scene.replace(**{k: (float(v[i]) if v.ndim == 1 else tuple(v[i]))
                               for k, v in params.items()}) for i in range(n)]
    assert_batch_equals_single(b, scenes, 40)
    assert list(b.channels) == ["dissipated"]            # on, because some arm damps
    assert b.channel("work").tolist() == [0.0] * n


def test_batch_command_policy_holds_per_arm_torques():
    scene = load_scene("release").replace(policy="command_gravity_compensation")
    torques = RNG.uniform(-2, 2, (3, 2))
    b = Batch(scene, count=3)
    b.set_command(torques[:, 0], torques[:, 1])
    b.run(30)
    assert_batch_equals_single(b, [scene] * 3, 30, commands=[tuple(t) for t in torques])


def test_batch_spans_several_chunks_and_resets(monkeypatch):
    monkeypatch.setattr(batch_module, "CHUNK", 3)
    scene = load_scene("release")
    q = RNG.uniform(-1, 1, (8, 2))
    b = Batch(scene, q)
    b.run(20)
    first = [a.copy() for a in b.state]
    scenes = [scene.replace(initial_positions=tuple(q[i])) for i in range(8)]
    assert_batch_equals_single(b, scenes, 20)
    b.reset()
    assert b.steps == 0 and np.array_equal(b.positions, q)
    b.run(10)
    b.run(10, threads=2)
    assert all(np.array_equal(x, y) for x, y in zip(first, b.state))


@pytest.mark.parametrize("kwargs, message", [
    ({"positions": [[0.0, float("nan")]]}, "positions of arm 0 is not finite"),
    ({"positions": np.zeros((3, 3))}, "must have shape"),
    ({"count": 2, "link_masses": [[1.0, 1.0], [1.0, -1.0]]}, "arm 1: link_masses must be positive"),
    ({"count": 2, "gravity": [9.81, -1.0]}, "arm 1: gravity"),
    ({"count": 1, "com_inertias": [[0.0, 0.0]], "com_distances": [[0.5, 0.0]]},
     "mass matrix becomes singular"),
    ({"count": 1, "step_size": 0.1}, "cannot vary per arm"),
    ({"count": 0}, "at least one arm"),
])
def test_batch_refuses_what_the_scene_refuses(kwargs, message):
    with pytest.raises(SceneError, match=message):
        Batch(load_scene("release"), **kwargs)


def test_batch_refuses_other_integrators_and_negative_steps():
    with pytest.raises(SceneError, match="rk4"):
        Batch(load_scene("release").replace(integrator="euler"))
    with pytest.raises(SceneError, match="negative"):
        Batch(load_scene("release")).run(-1)


def test_batch_command_reports_throughput_and_agreement(capsys):
    assert cli.main(["batch", "--count", "2000", "--duration", "0.1"]) == 0
    out = capsys.readouterr().out
    assert "M arm-steps/s" in out and "non-finite arms 0" in out
    agreement = float(out.rsplit("on 3 arms", 1)[1])
    assert agreement <= 1e-12


def test_batch_command_refuses_bad_counts(capsys):
    assert cli.main(["batch", "--count", "0"]) == 2
    assert "at least 1" in capsys.readouterr().err


# --- Every effect ----------------------------------------------------------------------

def full_state(scene, steps, command=None):
    """Every state entry of one arm: q, q̇, extra states (winding currents), every channel.
    A batch takes the stability plan's sub-steps only, never a tolerance's (accuracy.py):
    the arm it equals runs with tolerance 0."""
    sim = Simulator(scene.replace(tolerance=0.0))
    if command is not None:
        sim.set_command(*command)
    for _ in range(steps):
        sim.step()
    return sim, np.array(sim.state)


@pytest.mark.parametrize("name", preset_names())
def test_batch_equals_single_arm_for_every_preset_and_every_state_entry(name):
    scene = load_scene(name)
    if scene.friction is not None or scene.joint_limits is not None:
        # Switched arm by arm at located events: refused in one line, no traceback.
        with pytest.raises(SceneError, match="batch rollouts cannot run") as refused:
            Batch(scene, count=3)
        assert "\n" not in str(refused.value)
        scene = scene.replace(friction=None, joint_limits=None)
    q = np.asarray(scene.initial_positions) + RNG.uniform(-0.5, 0.5, (3, 2))
    qd = RNG.uniform(-1, 1, (3, 2))
    command = RNG.uniform(-2, 2, 2)
    b = Batch(scene, q, qd)
    b.set_command(*command)
    b.run(100)
    for i in range(3):
        sim, expected = full_state(scene.replace(initial_positions=tuple(q[i]),
                                                 initial_velocities=tuple(qd[i])), 100, command)
        assert (b.channels, b.extra, b.substeps) == (sim.channels, sim.extra, sim.substeps)
        got = np.array([a[i] for a in b.state])
        if sim.switching is not None:
            # A clamp of a state-dependent request: the arm locates its switches (events.py,
            # order 4), the batch clamps with MIN/MAX in each stage, whose kink costs RK4 its
            # order at the crossing (measured 5e-5 at h = 0.01 on effort_limited_hold). The
            # batch is that mode-free step exactly.
            assert np.max(np.abs(got - expected)) <= 1e-3, (name, i, got - expected)
            start, _ = full_state(scene.replace(initial_positions=tuple(q[i]),
                                                initial_velocities=tuple(qd[i])), 0, command)
            expected = np.array(mode_free(start, 100))
        assert np.max(np.abs(got - expected)) <= 1e-12, (name, i, got - expected)


@pytest.mark.parametrize("policy", ["gravity_compensation", "frozen_gravity"])
def test_batch_controller_model_believes_each_arms_own_unnamed_values(policy):
    """Unnamed controller_model keys are each arm's true values (per-arm gravity and links),
    not the batch's placeholder structure."""
    scene = load_scene("wrong_payload_model").replace(
        policy=policy, controller_model={"payload_mass": 0.0, "link_masses": [1.2, 0.9]})
    params = {"gravity": np.array([9.81, 3.7, 0.0]),
              "link_lengths": RNG.uniform(0.7, 1.3, (3, 2)),
              "com_distances": RNG.uniform(0.3, 0.6, (3, 2))}
    b = Batch(scene, count=3, **params)
    b.run(100)
    for i in range(3):
        arm = scene.replace(gravity=float(params["gravity"][i]),
                            link_lengths=tuple(params["link_lengths"][i]),
                            com_distances=tuple(params["com_distances"][i]))
        sim, expected = full_state(arm, 100)
        # (an arm without gravity compensates nothing: its simulator has no work channel,
        # the batch's stays 0 for it)
        got = dict(zip(("q1", "q2", "qd1", "qd2") + b.extra + b.channels, (a[i] for a in b.state)))
        expected = dict(zip(sim.state_names, expected))
        assert max(abs(got[k] - expected.get(k, 0.0)) for k in got) <= 1e-12, (i, got, expected)


def test_batch_sub_steps_for_its_stiffest_arm():
    """Per-arm damping beyond the scene's: the batch takes the stiffest arm's plan, stays
    finite, and equals that arm's own simulator; the others stay within RK4's error."""
    scene = load_scene("release")
    damping = np.array([0.0, 5.0, 100.0])
    b = Batch(scene, count=3, damping=damping)
    b.run(50)
    assert np.isfinite(np.stack(b.state)).all()
    stiffest, expected = full_state(scene.replace(damping=100.0), 50)
    assert b.substeps == stiffest.substeps > 1
    assert np.max(np.abs(np.array([a[2] for a in b.state]) - expected)) <= 1e-12
    for i in (0, 1):     # RK4 at h = 0.01 is ~1e-6 rad from exact on the release
        _, own = full_state(scene.replace(damping=float(damping[i])), 50)
        assert np.max(np.abs(np.array([a[i] for a in b.state])[:4] - own[:4])) <= 1e-5


def test_batch_of_arms_sharing_parameters_keeps_the_scenes_plan():
    scene = load_scene("geared_arm").replace(friction=None, joint_limits=None)
    assert Batch(scene, count=4).substeps == Simulator(scene).substeps == 1   # exponential_rk4
    rk4 = scene.replace(integrator="rk4")
    assert Batch(rk4, count=4).substeps == Simulator(rk4).substeps == 3
