"""A state the divergence check retracts never reaches an output: `arm-sim run` hands a step
to its CSV, bag and Rerun recording only once the check has confirmed it (the simulator
checks every guard.CHECK_EVERY steps and rolls back to the last sound state)."""
import csv

import numpy as np

from arm_sim_ros.physics.trust import guard
from arm_sim_ros.tools import cli

from recording.test_bag import read_bag
from recording.test_telemetry import read_back

H = 0.01


def test_rows_between_the_last_sound_check_and_a_diverged_one_reach_no_output(
        tmp_path, monkeypatch, capsys):
    # run() checks at its end too: its chunks (1, 2, 4 ... 128 steps, doubling while fast)
    # end at steps 127 and 255, so the checks at 128 and 192 fall inside the 128-step one
    sound, found = 2 * guard.CHECK_EVERY, 3 * guard.CHECK_EVERY  # checked sound, then diverged
    real = guard.divergence
    monkeypatch.setattr(cli, "CHECK_PERIOD", 1e9)     # chunks double, however busy the machine

    def diverges_at_the_second_check(sim, state):
        return "diverged (as this test says)" if sim.steps >= found else real(sim, state)

    monkeypatch.setattr(guard, "divergence", diverges_at_the_second_check)
    paths = {"csv": tmp_path / "run.csv", "rerun": tmp_path / "run.rrd", "bag": tmp_path / "bag"}
    code = cli.main(["run", "--scene", "damped_release", "--duration", "2", "--set", "tolerance=0",
                     "--csv", str(paths["csv"]), "--rerun", str(paths["rerun"]),
                     "--bag", str(paths["bag"])])
    err = capsys.readouterr().err
    assert code == 1 and "diverged (as this test says)" in err, err
    retracted = set(range(sound + 1, found))

    with open(paths["csv"]) as file:
        rows = list(csv.DictReader(file))
    steps = [round(float(row["t"]) / H) for row in rows]
    assert not retracted & set(steps)
    assert steps == [s for s in range(0, 201) if s not in retracted]
    # from the diverged check on, the rows hold the last sound state
    held = [row for row, step in zip(rows, steps) if step >= found]
    assert {(row["q1"], row["q2"]) for row in held} == {(rows[sound]["q1"], rows[sound]["q2"])}

    messages, _ = read_bag(paths["bag"])
    bag_steps = [round(stamp / 1e9 / H) for stamp, _, _ in messages["/joint_states"]]
    assert bag_steps and not retracted & set(bag_steps)

    angles = read_back(paths["rerun"])["joints/angle"]
    rerun_steps = np.rint(np.array(angles["sim_time"]) / 1e9 / H).astype(int)
    assert len(rerun_steps) == len(steps) and not retracted & set(rerun_steps.tolist())
