"""run_scenes: each scene's Outcome is what its own Simulator.run gives, bit for bit, whatever
runs it (a batch of its structure or the simulator alone), on any number of threads; a
sample that diverges, faults or cannot be built is an Outcome with its reason."""
import math
import os

import numpy as np
import pytest

from arm_sim_ros.physics.batch import Outcome, run_scenes
from arm_sim_ros.physics.compiled import build
from arm_sim_ros.physics.scene import load_scene
from arm_sim_ros.physics.simulator import Simulator

RNG = np.random.default_rng(46)
SENSORS = {"seed": 7, "rate": 500.0, "position_resolution": [0.0015339807878856412] * 2,
           "position_noise": [1e-4, 1e-4], "velocity": "differences", "delay": 0.002}


def off(scene):
    return scene.replace(estimate="off", tolerance=0.0)


def expected(scene, duration):
    """(q, qd, steps, substeps, max |residual|, accumulated error, status) of Simulator.run."""
    sim = Simulator(scene)
    largest = sim.run(duration)
    status = "diverged" if sim.diverged else "fault" if sim.refused_steps else "ok"
    return (tuple(sim.state[:2]), tuple(sim.state[2:4]), sim.steps, sim.substeps_taken,
            largest, sim.accumulated_error, status)


def got(outcome: Outcome):
    return (tuple(map(float, outcome.q)), tuple(map(float, outcome.qd)), outcome.steps, outcome.substeps,
            outcome.max_abs_residual, outcome.accumulated_error, outcome.status)


def same(a, b) -> bool:
    """Equal, NaN equal to NaN (the estimate of a run that has none)."""
    return repr(a) == repr(b)


def varied(name, count, **changes):
    scene = load_scene(name).replace(**changes)
    q = np.asarray(scene.initial_positions) + RNG.uniform(-0.3, 0.3, (count, 2))
    return [scene.replace(initial_positions=tuple(map(float, p))) for p in q]


CASES = {   # name: (scenes, duration)
    "release": (varied("release", 5, step_size=1e-3), 0.3),
    "release_masses": ([off(load_scene("release")).replace(link_masses=(m, 1.0))
                        for m in (0.5, 1.0, 2.0)], 0.5),
    "stick_slip": (varied("stick_slip", 3, estimate="off", tolerance=0.0), 1.0),
    "limit_impact": (varied("limit_impact", 3, estimate="off", tolerance=0.0), 1.0),
    "servo_reach": (varied("servo_reach", 3, estimate="off", tolerance=0.0), 0.2),
    "servo_hold": (varied("servo_hold", 3, estimate="off", tolerance=0.0), 0.2),
    "geared_arm": (varied("geared_arm", 2, estimate="off", tolerance=0.0), 0.05),
    "sensors": ([off(load_scene("release")).replace(step_size=1e-3, sensors=SENSORS | {"seed": s})
                 for s in (0, 1, 2**62)], 0.2),
    "sensed_servo": ([off(load_scene("servo_hold")).replace(
        sensors=SENSORS | {"seed": s}, command_delay=1e-3) for s in (3, 4)], 0.2),
    "estimated": (varied("release", 2), 0.3),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_each_outcome_is_its_scenes_own_run(case):
    scenes, duration = CASES[case]
    outcomes = run_scenes(scenes, duration)
    for scene, outcome in zip(scenes, outcomes):
        assert outcome.status == "ok" and outcome.reason == ""
        assert same(got(outcome), expected(scene, duration)), case


def test_samples_that_diverge_fault_or_cannot_run_are_outcomes_with_their_reason():
    good = off(load_scene("release"))
    diverging = load_scene("payload_release").replace(payload={"mass": 1e6}, tolerance=0.0)
    faulting = good.replace(initial_velocities=(1e150, 1e150))
    uneven = good.replace(step_size=0.003)          # 0.1 s is not a whole number of its steps
    outcomes = run_scenes([good, diverging, faulting, uneven, good], 0.1)
    assert [o.status for o in outcomes] == ["ok", "diverged", "fault", "refused", "ok"]
    assert outcomes[1].reason.startswith("the step to t = ") and "diverged" in outcomes[1].reason
    assert "would make" in outcomes[2].reason
    assert outcomes[3].reason.startswith("duration 0.1 s is not a whole number of steps")
    assert math.isnan(outcomes[3].q[0]) and outcomes[3].steps == 0
    for scene, outcome in zip([good, diverging, faulting], outcomes):
        assert same(got(outcome), expected(scene, 0.1))


def trajectory(scene, duration):
    """(t, q, qd, tau) of every step from t = 0, as Simulator.run's callback sees them."""
    sim = Simulator(scene)
    rows = [(sim.time, *sim.state[:4], *sim.joint_torque())]
    sim.run(duration, lambda s: rows.append((s.time, *s.state[:4], *s.joint_torque())))
    rows = np.array(rows)
    return rows[:, 0], rows[:, 1:3], rows[:, 3:5], rows[:, 5:7]


def observed(threads):
    """The calls of observe (indices, first time, times) of a run on `threads`, each row's
    trajectory checked against its simulator's."""
    scenes = (varied("release", 3, step_size=1e-3, estimate="off", tolerance=0.0)
              + varied("stick_slip", 2, estimate="off", tolerance=0.0))
    duration = 1.2                                 # more than one chunk at h = 1 ms
    seen = {}
    calls = []

    def observe(indices, t, q, qd, tau):
        calls.append((tuple(indices), t[0], len(t)))
        for row, i in enumerate(indices):
            parts = seen.setdefault(i, [[], [], [], []])
            for part, value in zip(parts, (t, q[row], qd[row], tau[row])):
                part.append(value)
    run_scenes(scenes, duration, observe=observe, threads=threads)
    for i, scene in enumerate(scenes):
        for part, want in zip(seen[i], trajectory(scene, duration)):
            assert np.array_equal(np.concatenate(part), want)
    return calls


def test_observe_hands_out_every_rows_trajectory_in_time_order_whatever_the_threads():
    calls = observed(1)
    assert calls == observed(2)
    assert calls[0][1] == 0.0 and any(c[1] > 0.0 for c in calls)    # several chunks


@pytest.mark.skipif(os.environ.get("ARM_SIM_COMPILED") == "0" or build.numba is None,
                    reason="no compiled path (no numba, or .ci/run's pure-Python pass: its "
                    "compiled pass runs this)")
@pytest.mark.parametrize("case", ["release_masses", "servo_reach", "servo_hold", "sensors",
                                  "sensed_servo", "estimated"])
def test_samples_of_one_structure_run_together_in_compiled_calls(case, monkeypatch):
    """One group of rows (one compiled call per chunk for them all), no step in Python."""
    scenes, duration = CASES[case]
    taken, groups = [], set()
    python_step = Simulator.step_in_python
    monkeypatch.setattr(Simulator, "step_in_python",
                        lambda sim: (taken.append(sim.steps), python_step(sim)))
    run_scenes(scenes, duration, observe=lambda indices, *rows: groups.add(tuple(indices)))
    assert groups == {tuple(range(len(scenes)))} and taken == []


def test_outcomes_do_not_depend_on_the_thread_count():
    scenes = CASES["release"][0] + CASES["sensors"][0] + CASES["servo_hold"][0]
    one, two = (run_scenes(scenes, 0.2, threads=n) for n in (1, 2))
    assert [repr(got(o)) for o in one] == [repr(got(o)) for o in two]
