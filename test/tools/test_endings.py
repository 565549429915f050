"""How recordings end (issue 16): a flood never delays a stop, every stopping signal closes
the bag, a kill -9 or a full disk keeps what was written, an empty bag says when it began,
the last diagnostics say how the run ended, and what DDS refuses is one line, exit 2.

Subprocesses run `python -m arm_sim_ros.tools.cli`. DDS is loopback only, tagged with this
process (a concurrent run of the suite never meets it), on domain ids 80-89.
"""
import logging
import os
import re
import signal
import subprocess
import sys
import threading
import time

import pytest
import yaml
from rosbags.rosbag2 import Reader

from arm_sim_ros.interface import NODE_TOPICS, WARN
from arm_sim_ros.physics.scene import load_scene
from arm_sim_ros.physics.simulator import Simulator
from arm_sim_ros.recording.bags.bag import TYPESTORE, BagWriter
from arm_sim_ros.tools import cli
from arm_sim_ros.tools.run.bag import RunBag

wire = pytest.importorskip("arm_sim_ros.node.wire.messages")
ISOLATED = wire.loopback_config(f"arm_sim_test_endings_{os.getpid()}")
PYTHON = [sys.executable, "-c"]
# The CLI, with the constants a test shortens set first (python -c SCRIPT ARGS...).
CLI = ("import sys\nfrom arm_sim_ros.tools.wire import record\n{setup}\n"
       "from arm_sim_ros.tools.cli import main\nsys.exit(main(sys.argv[1:]))")
# ... and under a file-size limit: SIGXFSZ ignored, so that writes fail with EFBIG.
LIMITED = ("import resource, signal\nsignal.signal(signal.SIGXFSZ, signal.SIG_IGN)\n"
           "resource.setrlimit(resource.RLIMIT_FSIZE, ({limit}, {limit}))\n")


def dds_env(domain, **more):
    return os.environ | {"ROS_DOMAIN_ID": str(domain), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
                         "CYCLONEDDS_URI": ISOLATED, "ROS_STATIC_PEERS": ""} | more


def start_cli(*argv, env=None, setup=""):
    return subprocess.Popen([*PYTHON, CLI.format(setup=setup), *map(str, argv)], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


class Lines:
    """A subprocess's stderr, read line by line as it comes."""

    def __init__(self, stream):
        self.lines = []
        self._thread = threading.Thread(target=lambda: self.lines.extend(stream), daemon=True)
        self._thread.start()

    def wait_for(self, text, timeout=20.0):
        deadline = time.monotonic() + timeout
        while not any(text in line for line in self.lines):
            assert time.monotonic() < deadline, f"never said {text!r}: {self.lines}"
            time.sleep(0.02)

    def text(self):
        self._thread.join(5)
        return "".join(self.lines)


def writer_for(participant, topic, keep_all=True):
    """keep_all: test_bag's writer (every sample kept until acknowledged, a write waiting for
    room as long as a busy machine needs: the default 100 ms once timed out in CI); else the
    node's keep-last QoS."""
    from recording.test_bag import writer_for as keeping_writer
    if keep_all:
        return keeping_writer(participant, topic, wire.JointState)
    from cyclonedds.pub import DataWriter
    from cyclonedds.topic import Topic
    return DataWriter(participant, Topic(participant, wire.ros_topic(topic), wire.JointState),
                      qos=wire.default_qos(wire.JointState))


def wait_matched(writer, timeout=20.0):
    deadline = time.monotonic() + timeout
    while not wire.matched(writer):
        assert time.monotonic() < deadline, "the recorder never subscribed"
        time.sleep(0.01)


def joint_state(k):
    return wire.JointState(header=wire.Header(stamp=wire.Time(k, 0)), name=["a", "b"],
                           position=[float(k), 0.5], velocity=[0.0, 1.0], effort=[2.0, -1.0])


def bag_messages(path):
    with Reader(path) as reader:
        return [(c.topic, t, TYPESTORE.deserialize_cdr(raw, c.msgtype))
                for c, t, raw in reader.messages()]


def metadata(path):
    return yaml.safe_load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]


def finish(process, timeout=20):
    try:
        return process.communicate(timeout=timeout)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()


# --- 1. a flood never delays a stop; progress as it goes --------------------------------------

def test_record_reports_as_it_goes_and_stops_promptly_under_a_flood(tmp_path):
    domain, path = 80, tmp_path / "bag"
    process = start_cli("record", path, env=dds_env(domain), setup="record.REPORT_SECONDS = 0.3")
    err = Lines(process.stderr)
    try:
        err.wait_for("/joint_states no publisher yet")
        writer = writer_for(wire.make_participant(domain, ISOLATED), "/joint_states", keep_all=False)
        wait_matched(writer)
        flooding = True

        def flood():   # as fast as this process can: faster than the recorder can write
            k = 0
            while flooding:
                writer.write(joint_state(k))
                k += 1
        thread = threading.Thread(target=flood)
        thread.start()
        try:
            time.sleep(1.0)
            process.send_signal(signal.SIGTERM)
            sent = time.monotonic()
            process.wait(timeout=15)
            stopped_after = time.monotonic() - sent
        finally:
            flooding = False
            thread.join()
        out, _ = process.communicate(timeout=5)
    finally:
        finish(process)
    assert process.returncode == 0, err.text()
    # A bound, not a timing: draining the backlog took 75 s before; a bounded stop takes
    # ~0.5 s on a quiet machine (README), a few s on a loaded CI runner.
    assert stopped_after < 10.0, f"SIGTERM honoured after {stopped_after:.1f} s"
    # Counts per topic while it records, a line every REPORT_SECONDS:
    assert any(re.match(r"record: \d+ s: /joint_states [1-9]", line) for line in err.lines), err.text()
    messages = bag_messages(path)
    assert len(messages) > 0 and f"/joint_states {len(messages)}" in out


def write_acknowledged(domain, count):
    """JointStates 0 .. count - 1 on /joint_states, each acknowledged by the recorder."""
    writer = writer_for(wire.make_participant(domain, ISOLATED), "/joint_states")
    wait_matched(writer)
    for k in range(count):
        writer.write(joint_state(k))
    assert writer.wait_for_acks(60_000_000_000)


# --- 2. every stopping signal closes the bag ---------------------------------------------------

def test_record_closes_the_bag_on_sighup(tmp_path):
    domain, path = 81, tmp_path / "bag"
    process = start_cli("record", path, env=dds_env(domain))
    try:
        write_acknowledged(domain, 300)
        process.send_signal(signal.SIGHUP)
        out, err = finish(process)
    finally:
        finish(process)
    assert process.returncode == 0, err
    assert [m.position[0] for _, _, m in bag_messages(path)] == [float(k) for k in range(300)]


def test_run_bag_stopped_by_sighup_is_closed_and_its_last_diagnostics_say_so(tmp_path):
    path = tmp_path / "bag"
    process = start_cli("run", "--duration", "10000", "--bag", path)
    try:
        deadline = time.monotonic() + 20
        while not (path / "metadata.yaml").exists() or metadata(path)["message_count"] == 0:
            assert time.monotonic() < deadline
            time.sleep(0.05)
        process.send_signal(signal.SIGHUP)
        _, err = finish(process)
    finally:
        finish(process)
    assert process.returncode == 130 and "Traceback" not in err, err
    diagnostics = [m for topic, _, m in bag_messages(path) if topic == "/diagnostics"]
    (status,) = diagnostics[-1].status
    assert status.level == WARN and "stopped" in status.message and "10000 s" in status.message
    assert all(d.status[0].message == "running" for d in diagnostics[:-1])


# --- 4. kill -9 keeps every chunk written ------------------------------------------------------

def test_a_killed_run_bag_opens_and_holds_a_gapless_run(tmp_path):
    path = tmp_path / "bag"
    process = start_cli("run", "--duration", "10000", "--bag", path)
    try:
        deadline = time.monotonic() + 120   # a hang guard: a loaded machine is slow
        while not ((path / "metadata.yaml").exists() and metadata(path)["message_count"] > 5000):
            assert time.monotonic() < deadline
            time.sleep(0.05)
        process.kill()
        process.wait()
    finally:
        finish(process)
    info = metadata(path)
    messages = bag_messages(path)
    stamps = [t for topic, t, _ in messages if topic == "/joint_states"]
    assert len(messages) == info["message_count"] > 5000
    origin = stamps[0]                 # bag time: the wall clock at start + simulated time
    assert [t - origin for t in stamps] == [k * 10_000_000 for k in range(len(stamps))]
    assert info["duration"]["nanoseconds"] == stamps[-1] - origin   # every tick, from t = 0


def test_a_killed_recorder_keeps_what_it_received_a_second_before(tmp_path):
    domain, path = 82, tmp_path / "bag"
    process = start_cli("record", path, env=dds_env(domain))
    try:
        write_acknowledged(domain, 500)
        deadline = time.monotonic() + 10     # within CHUNK_SECONDS (1 s) it is on disk
        while not (path / "metadata.yaml").exists() or metadata(path)["message_count"] < 500:
            assert time.monotonic() < deadline
            time.sleep(0.05)
        process.kill()
        process.wait()
    finally:
        finish(process)
    assert [m.position[0] for _, _, m in bag_messages(path)] == [float(k) for k in range(500)]


# --- 3. a file-size limit (or a full disk) ends in one line and a closed output -------------------

def limited_run(tmp_path, limit, *argv):
    process = start_cli(*argv, setup=LIMITED.format(limit=limit))
    _, err = finish(process, timeout=60)
    assert process.returncode == 2, err
    assert err.count("\n") == 1 and "Traceback" not in err and "File too large" in err, err
    return err


def test_run_bag_past_a_file_size_limit_is_closed_with_what_fit(tmp_path):
    path = tmp_path / "bag"
    err = limited_run(tmp_path, 1_500_000, "run", "--duration", "10000", "--bag", path)
    messages = bag_messages(path)
    assert 0 < len(messages) == metadata(path)["message_count"]
    assert f"holds the {len(messages)} messages that fit" in err
    assert 1_450_000 < (path / f"{path.name}.mcap").stat().st_size <= 1_500_000   # all that fit
    assert sorted(p.name for p in path.iterdir()) == ["bag.mcap", "metadata.yaml"]


def test_run_csv_past_a_file_size_limit_ends_with_whole_rows(tmp_path):
    path = tmp_path / "run.csv"
    err = limited_run(tmp_path, 200_000, "run", "--duration", "10000", "--csv", path)
    text = path.read_text()
    rows = text.splitlines()
    assert text.endswith("\n") and len(rows) > 100
    assert {len(row.split(",")) for row in rows} == {len(rows[0].split(","))}
    assert f"holds the {len(rows) - 1} rows that fit (up to t = {rows[-1].split(',')[0]} s)" in err


def test_record_past_a_file_size_limit_is_closed_with_what_fit(tmp_path):
    domain, path = 83, tmp_path / "bag"
    process = start_cli("record", path, env=dds_env(domain),
                        setup=LIMITED.format(limit=150_000))
    try:
        writer = writer_for(wire.make_participant(domain, ISOLATED), "/joint_states",
                            keep_all=False)
        wait_matched(writer)
        k = 0
        while process.poll() is None and k < 20_000:
            writer.write(joint_state(k))
            k += 1
        _, err = finish(process)
    finally:
        finish(process)
    assert process.returncode == 2 and "File too large" in err and "Traceback" not in err, err
    assert err.strip().splitlines()[-1].startswith("arm-sim: error: cannot write bag")
    messages = bag_messages(path)
    assert len(messages) > 100 and f"holds the {len(messages)} messages that fit" in err
    assert 100_000 < (path / f"{path.name}.mcap").stat().st_size <= 150_000


# --- 5. an empty bag begins when it was opened; the last diagnostics say how the run ended -------

def test_an_empty_bag_starts_when_it_was_opened(tmp_path):
    with BagWriter(tmp_path / "bag", start_ns=1_700_000_000_123_456_789) as writer:
        writer.add_topic("/joint_states", NODE_TOPICS["/joint_states"])
    info = metadata(tmp_path / "bag")
    assert info["starting_time"]["nanoseconds_since_epoch"] == 1_700_000_000_123_456_789
    assert info["message_count"] == 0 and info["duration"]["nanoseconds"] == 0
    assert bag_messages(tmp_path / "bag") == []


def test_a_recording_that_waited_in_vain_leaves_no_bag(tmp_path, monkeypatch, capsys):
    """It left an empty bag (exit 0), whose name the next try could not use."""
    for name, value in dds_env(84).items():
        monkeypatch.setenv(name, value)
    assert cli.main(["record", "--duration", "0.3", "--wait", "0.5", str(tmp_path / "bag")]) == 1
    assert capsys.readouterr().err.splitlines()[-1].startswith("record: no message arrived on ")
    assert not (tmp_path / "bag").exists()


def test_the_last_diagnostics_of_a_run_say_how_it_ended(capsys, tmp_path):
    assert cli.main(["run", "--duration", "2", "--bag", str(tmp_path / "done")]) == 0
    messages = bag_messages(tmp_path / "done")
    origin = messages[0][1]            # the first JointState, at simulated t = 0
    diagnostics = [(t, m.status[0]) for topic, t, m in messages if topic == "/diagnostics"]
    assert [t - origin for t, _ in diagnostics] == [1_000_000_000, 2_000_000_000]
    assert diagnostics[0][1].message == "running"
    assert diagnostics[-1][1].message == "finished: ran its 2 s" and diagnostics[-1][1].level == 0
    # Stopped early (a signal, or another output that failed):
    sim = Simulator(load_scene("release").replace(duration=5.0))
    recorder = RunBag(tmp_path / "stopped", publish_steps=1)
    recorder.start(sim)
    for _ in range(30):
        sim.step()
        recorder.step(sim)
    recorder.stop_reason = "SIGTERM"
    recorder.finish(sim)
    (status,) = bag_messages(tmp_path / "stopped")[-1][2].status
    assert status.level == WARN
    assert status.message == "stopped by SIGTERM at t = 0.300000 s, before the end of its 5 s"


# --- 6, 7. what DDS and argparse refuse: one line, exit 2, nothing left behind -----------------

NODE = ["--transport", "dds", "--quiet", "--duration", "0.1"]
SEND = ["send-torque", "--once", "--wait", "0.1"]


@pytest.mark.parametrize("main, argv, domain, env, named", [
    ("arm-sim", [*SEND, "--topic", "bad topic", "1", "2"], 86, {}, "--topic 'bad topic'"),
    ("arm-sim", ["record", "D", "--topics", "/a b:JointState"], 86, {}, "'/a b'"),
    ("arm-sim", ["record", "D", "--topics", "/a//b:JointState"], 86, {}, "'//'"),
    ("arm-sim", ["record", "D"], 86, {"CYCLONEDDS_URI": "<bad"}, "CYCLONEDDS_URI"),
    ("arm-sim", [*SEND, "1", "2"], 86, {"CYCLONEDDS_URI": "<bad"}, "CYCLONEDDS_URI"),
    ("arm-sim", [*SEND, "1", "2"], 86, {"ROS_DOMAIN_ID": "abc"}, "ROS_DOMAIN_ID"),
    ("arm-sim", ["record", "D"], 86, {"ROS_AUTOMATIC_DISCOVERY_RANGE": "bogus"},
     "ROS_AUTOMATIC_DISCOVERY_RANGE"),
    ("arm_sim_node", [*NODE, "--ros-args", "-r", "__ns:=/a b"], 87, {}, "'/a b/joint_states'"),
])
def test_what_dds_refuses_is_one_line_and_leaves_nothing_behind(capfd, monkeypatch, tmp_path,
                                                                main, argv, domain, env, named):
    from arm_sim_ros.node.main import main as node_main

    for name, value in (dds_env(domain) | env).items():
        monkeypatch.setenv(name, value)
    monkeypatch.setattr(signal, "signal", lambda *args: None)   # the node's SIGTERM handler
    root = logging.getLogger()                                 # ... and its log handler
    monkeypatch.setattr(root, "handlers", list(root.handlers))
    monkeypatch.setattr(root, "level", root.level)
    monkeypatch.chdir(tmp_path)
    assert (cli.main if main == "arm-sim" else node_main)(argv) == 2
    err = capfd.readouterr().err           # what Cyclone prints on fd 2 too
    assert err.count("\n") == 1 and named in err and err.startswith(f"{main}: error: "), err
    assert list(tmp_path.iterdir()) == []  # `record D` left no D behind


def test_a_node_with_a_configuration_cyclone_refuses_is_one_line_and_exit_2():
    process = subprocess.Popen([sys.executable, "-m", "arm_sim_ros.node.main", *NODE],
                               env=dds_env(88, CYCLONEDDS_URI="<bad"), stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
    _, err = finish(process, timeout=60)
    assert process.returncode == 2 and err.count("\n") == 1, err
    assert err.startswith("arm_sim_node: error: CYCLONEDDS_URI='<bad' is a configuration")


def test_send_torque_says_it_needs_two_torques(capsys):
    assert cli.main(["send-torque", "1.0"]) == 2
    err = capsys.readouterr().err
    assert "two torques" in err and "TAU1 TAU2" in err and err.count("\n") == 1


@pytest.mark.parametrize("name", ["joint_states", "/joint_states", "/a/b_2/c", "A_b", "/_x"])
def test_topic_names_rcl_accepts(name):
    assert wire.check_topic_name(name) == name
    assert wire.ros_topic(name) == "rt/" + name.lstrip("/")


@pytest.mark.parametrize("name, reason", [
    ("", "empty"), ("a b", "' '"), ("/a//b", "'//'"), ("/a/", "ends with '/'"),
    ("1a", "digit"), ("/a/2b", "digit"), ("/a-b", "'-'"), ("~/x", "substitutions"),
    ("/{node}/x", "substitutions"), ("/é", "'é'"), ("/" + "a" * 247, "longer than 247"),
])
def test_topic_names_rcl_refuses(name, reason):
    with pytest.raises(wire.DiscoveryError, match=reason):
        wire.ros_topic(name)
