"""A diverged state never reaches an output (issue 39): the simulator checks every state as
it is made (physics/trust/guard.py) and keeps the last sound one, so `arm-sim run` hands
each step to its CSV, bag and Rerun recording as it is taken; a NaN coming after a
diverged state changes nothing, and neither does how the run is cut into calls (the
command line cuts it by wall time: a cold compile cut it otherwise than a warm one)."""
import csv

import numpy as np
import pytest

from arm_sim_ros.physics.scene import load_scene
from arm_sim_ros.physics.simulator import Simulator
from arm_sim_ros.physics.trust import guard
from arm_sim_ros.tools import cli

from recording.test_bag import read_bag
from recording.test_telemetry import read_back

H = 0.01
HUNT = [("1e4", "0"), ("3e5", "0"), ("1e6", "0"), ("3e6", "0"), ("1e6", "5e-5")]   # issue 39


def rows_of(path):
    with open(path) as file:
        return list(csv.DictReader(file))


def payload_run(tmp_path, capsys, mass, tolerance, name="run.csv"):
    path = tmp_path / name
    code = cli.main(["run", "--scene", "payload_release", "--set", f"payload.mass={mass}",
                     "--tolerance", tolerance, "--csv", str(path), "--force"])
    return code, capsys.readouterr().err, rows_of(path)


@pytest.mark.parametrize("mass, tolerance", HUNT)
def test_a_state_that_diverged_before_a_nan_reaches_no_row(mass, tolerance, tmp_path, capsys):
    """payload_release with a 1e4 kg payload at tolerance 0 diverged while finite, then
    made NaN before the old 64-step check: its CSV held q1 = -1.6e16 rad, residual 8.6e74 J."""
    code, err, rows = payload_run(tmp_path, capsys, mass, tolerance)
    sim = Simulator(load_scene("payload_release").replace(
        payload={"mass": float(mass)}, tolerance=float(tolerance)))
    sim.run(0.5)
    scale = guard.scale(sim, sim.state)            # the energy in play at the run's end
    assert len(rows) == 51 and all(abs(float(row["residual"])) <= scale for row in rows)
    assert max(abs(float(row[q])) for row in rows for q in ("q1", "q2")) < 10.0
    if code == 1:
        assert "diverged" in err and "holding the last sound state" in err


@pytest.mark.parametrize("mass, tolerance", HUNT)
@pytest.mark.parametrize("compiled", ["0", "1"])
def test_the_rows_do_not_depend_on_how_the_run_is_cut(mass, tolerance, compiled, tmp_path,
                                                      capsys, monkeypatch):
    """Chunks of one step each, and chunks doubling up to the end: the same rows, the same
    fault, the same exit code, on either path."""
    monkeypatch.setenv("ARM_SIM_COMPILED", compiled)
    outcomes = []
    for period, name in ((0.0, "one.csv"), (1e9, "doubling.csv")):
        monkeypatch.setattr(cli, "CHECK_PERIOD", period)
        code, err, rows = payload_run(tmp_path, capsys, mass, tolerance, name)
        outcomes.append((code, [line for line in err.splitlines() if "fault" in line], rows))
    assert outcomes[0] == outcomes[1]


def test_a_step_found_diverged_holds_the_state_before_in_every_output(tmp_path, monkeypatch,
                                                                     capsys):
    """Diverged (as this test says) at step 150, between the old 64-step checks: every step
    has its row, in the CSV, the bag and the recording; from step 150 on the rows hold the
    state of step 149. On the pure-Python path: the compiled loop checks with its own
    copy of guard.divergence, which no monkeypatch reaches."""
    found = 150
    real = guard.divergence

    def diverges_at(sim, state, residual):
        return "diverged (as this test says)" if sim.steps >= found else real(sim, state,
                                                                              residual)

    monkeypatch.setattr(guard, "divergence", diverges_at)
    monkeypatch.setenv("ARM_SIM_COMPILED", "0")
    paths = {"csv": tmp_path / "run.csv", "rerun": tmp_path / "run.rrd", "bag": tmp_path / "bag"}
    code = cli.main(["run", "--scene", "damped_release", "--duration", "2", "--set", "tolerance=0",
                     "--csv", str(paths["csv"]), "--rerun", str(paths["rerun"]),
                     "--bag", str(paths["bag"])])
    err = capsys.readouterr().err
    assert code == 1 and "diverged (as this test says)" in err, err
    rows = rows_of(paths["csv"])
    steps = [round(float(row["t"]) / H) for row in rows]
    assert steps == list(range(0, 201))
    held = {(row["q1"], row["q2"]) for row, step in zip(rows, steps) if step >= found}
    assert held == {(rows[found - 1]["q1"], rows[found - 1]["q2"])}

    messages, _ = read_bag(paths["bag"])
    joint_states = [message for _, message, _ in messages["/joint_states"]]
    stamps = [m.header.stamp.sec + m.header.stamp.nanosec / 1e9 for m in joint_states]
    assert [round(t / H) for t in stamps] == steps       # every step: 100 Hz at h = 10 ms
    assert {tuple(m.position) for m in joint_states[found:]} == {
        tuple(joint_states[found - 1].position)}

    angles = read_back(paths["rerun"])["joints/angle"]
    rerun_steps = np.rint(np.array(angles["sim_time"]) / 1e9 / H).astype(int)
    assert rerun_steps.tolist() == steps
