"""A sweep on a Dask cluster (two worker processes) writes the table one process writes,
byte for byte, and so does `arm-sim sweep --scheduler`."""
import distributed

import arm_sim_ros
from arm_sim_ros.tools import cli

VARY = {"payload.mass": "0.2,1.0", "friction.coulomb": "uniform:0.0:0.5",
        "sensors.seed": "integers:0:4294967295"}


def test_a_local_cluster_of_two_processes_gives_the_same_table(capsys, tmp_path, monkeypatch):
    monkeypatch.setenv("ARM_SIM_COMPILED", "0")        # the workers inherit it
    here = arm_sim_ros.sweep("servo_reach", VARY, samples=3, seed=2, duration=0.05, workers=1)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  protocol="tcp", host="127.0.0.1",
                                  dashboard_address=None) as cluster:
        there = arm_sim_ros.sweep("servo_reach", VARY, samples=3, seed=2, duration=0.05,
                                  scheduler=cluster.scheduler_address)
        out = tmp_path / "dask.csv"
        code = cli.main(["sweep", "servo_reach", *(x for k, v in VARY.items()
                                                   for x in ("--vary", f"{k}={v}")),
                         "--samples", "3", "--seed", "2", "--duration", "0.05",
                         "--scheduler", cluster.scheduler_address, "-o", str(out)])
    assert there.text == here.text and there.counts["ok"] == 6
    assert code == 0 and out.read_text() == here.text
    assert f"on the Dask cluster at {cluster.scheduler_address}" in capsys.readouterr().out


def test_a_scheduler_nobody_answers_is_one_line_and_no_file(capsys, tmp_path):
    out = tmp_path / "none.csv"
    code = cli.main(["sweep", "release", "--vary", "gravity=1", "--duration", "0.01",
                     "--scheduler", "tcp://127.0.0.1:9", "-o", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and "--scheduler tcp://127.0.0.1:9" in err and err.count("\n") == 1
    assert not out.exists()
