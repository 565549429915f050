"""Issue 39: every `arm-sim fit` ends within the bounds it states and says why it stopped;
its verdict (exit code and JSON) says whether the model explains the recording; no input
ends in a traceback; no list option takes a duplicate."""
from __future__ import annotations

import math
import shutil
import socket
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from arm_sim_ros.interface import JOINT_NAMES
from arm_sim_ros.tools import cli
from arm_sim_ros.tools.fit import bounds, command
from arm_sim_ros.tools.fit.data import FitError, read_recording

from tools.test_fit import base_args, csv_file, fit, short_bag, write_bag  # noqa: F401
from tools.test_fit_reference import recording


def rows(rec, time_unit=1.0):
    return np.column_stack([rec.t * time_unit, rec.q, rec.qd, rec.tau]).tolist()


# --- duplicates ----------------------------------------------------------------------------

def test_a_list_option_never_takes_a_duplicate(capsys, short_bag):
    """--joint-names shoulder_joint,shoulder_joint was taken (damping 21.98 ± 0.93 against
    a truth of 0.3, "converged", exit 0); so is every other list: the recordings, --free,
    --set."""
    cases = {
        "names shoulder_joint twice": ["--joint-names", "shoulder_joint,shoulder_joint",
                                       "--free", "damping"],
        "is given twice: a recording counts once": [short_bag, "--free", "damping"],
        "--free names damping and damping[0]: the same number twice": [
            "--free", "damping,damping[0]"],
        "--set damping is given twice": ["--set", "damping=0.1", "--set", "damping=0.2",
                                         "--free", "payload.mass"],
    }
    for expected, args in cases.items():
        assert expected in fit(capsys, short_bag, *args, code=2), expected


# --- the verdict ---------------------------------------------------------------------------

def test_a_model_that_explains_the_recording_says_so_in_its_exit_code_and_json(
        capsys, short_bag):
    outcome = fit(capsys, short_bag, *base_args(damping="0.7,0.1"), "--free", "damping",
                  "--starts", "1", "--workers", "1")
    verdict = outcome["verdict"]
    assert outcome["explains"] is verdict["explains"] is True
    assert verdict["worst_noise_multiple"] <= bounds.EXPLAINED
    assert "2 x the noise" in verdict["rule"]
    assert outcome["stopped"].startswith("converged")
    assert outcome["bounds"] == {"evaluations_per_start": 60, "seconds": bounds.DEFAULT_SECONDS,
                                 "steps_per_sample": bounds.MAX_STEPS_PER_SAMPLE}


def test_a_model_that_misses_the_recording_converges_but_exits_3_with_its_verdict(
        capsys, short_bag, tmp_path):
    """The base scene without the arm's friction, damping free: it converges to a model that
    misses the validation by many times the noise. Converged, the warning, and the verdict:
    exit 3, the outputs written."""
    fitted = tmp_path / "fitted.yaml"
    status = cli.main(["fit", short_bag, *base_args(hidden=("friction.coulomb",)), "--free",
                       "damping", "--starts", "1", "--workers", "1", "-o", str(fitted)])
    out, err = capsys.readouterr()
    assert status == bounds.UNEXPLAINED_CODE, err
    assert "verdict: the model does NOT explain the recording" in out
    assert "warning: the fitted simulation misses the recording" in out
    assert fitted.exists()


# --- bounds --------------------------------------------------------------------------------

@pytest.mark.parametrize("unit, name", [(1e3, "ms"), (1e9, "ns")])
def test_time_stamps_in_ms_or_ns_are_refused_before_anything_runs(capsys, tmp_path, unit, name):
    """Read as seconds, 2 ms samples at 1e9 sub-steps each ran without end."""
    path = csv_file(tmp_path / f"{name}.csv", rows(recording(1.0)[0], unit))
    line = fit(capsys, path, *base_args(), "--free", "damping", code=2)
    assert f"samples {0.002 * unit:g} s apart, under 1 Hz: time stamps in ms or ns?" in line


@pytest.mark.parametrize("option, expected", [
    (["--step", "1e-6"], "take 2000 steps of 1e-06 s"),
    (["--segment", "1e-9"], "leave a segment of 2 samples; a fit needs at least 10"),
    (["--max-seconds", "nan"], "--max-seconds nan must be a positive number"),
    (["--max-seconds", "0"], "--max-seconds 0 must be a positive number")])
def test_options_that_would_not_end_are_refused(capsys, short_bag, option, expected):
    args = [a for a in base_args() if a not in ("--step", "0.002")] if "--step" in option \
        else base_args()
    assert expected in fit(capsys, short_bag, *args, "--free", "damping", *option, code=2)


def test_a_recording_too_long_to_hold_is_refused_up_front_with_its_size(capsys, tmp_path):
    """A dense Jacobian grows as samples x segments: 1 000 000 rows asked for 76.3 GiB
    (a traceback). Refused before anything runs, with the size and what to do."""
    n = 60_000          # 120 s at 500 Hz, cut into 0.1 s segments
    t = np.arange(n) * 0.002
    path = csv_file(tmp_path / "long.csv", np.column_stack(
        [t, np.sin(t), np.cos(t), np.cos(t), -np.sin(t), 0 * t, 0 * t]).tolist())
    line = fit(capsys, path, *base_args(), "--free", "damping", "--segment", "0.1", code=2)
    assert "residuals for" in line and "GiB, beyond 1 GiB" in line
    assert "fit a shorter stretch of the recording" in line


def test_an_impossible_recording_stops_at_the_wall_time_bound_saying_so(capsys, tmp_path):
    """A hanging arm recorded as (nearly) still off its equilibrium, with no torque: the
    damping climbs without end and each evaluation got slower (40 min, no line). It stops at
    --max-seconds with its best point; the damping stops where the replay would pass the
    steps-per-sample bound. (It creeps at 1 mrad/s: a recording that does not move at all
    identifies nothing and is refused before the fit, test_fit_verdicts.py.)"""
    path = csv_file(tmp_path / "still.csv", [[k * 0.01, -math.pi / 2 + 0.5 + 1e-5 * k, 0,
                                              1e-3, 0, 0, 0] for k in range(100)])
    started = time.monotonic()
    line = fit(capsys, path, "--free", "damping", "--workers", "1", "--starts", "1",
               "--max-seconds", "3", code=bounds.STOPPED_CODE)
    assert "stopped at the wall-time bound (3 s, --max-seconds) before it converged" in line
    assert "best point: damping = " in line
    assert time.monotonic() - started < 60      # one evaluation past the bound at most


# --- no tracebacks -------------------------------------------------------------------------

@pytest.fixture(scope="module")
def good_bag(tmp_path_factory):
    return write_bag(tmp_path_factory.mktemp("corrupt") / "good", recording(1.0)[0])


COPIES = iter(range(10 ** 9))


def corrupted(good_bag, where, data: bytes):
    """A copy of `good_bag` with `data` written over its MCAP from `where` (a fraction of
    its length), or the MCAP cut there where `data` is empty."""
    copy = Path(f"{good_bag}_{next(COPIES)}")
    shutil.copytree(good_bag, copy)
    (mcap,) = copy.glob("*.mcap")
    raw = bytearray(mcap.read_bytes())
    at = int(where * len(raw))
    if data:
        raw[at:at + len(data)] = data
    else:
        del raw[at:]
    mcap.write_bytes(bytes(raw))
    return str(copy)


def assert_read_or_refused(path):
    try:
        read_recording(path, JOINT_NAMES)
    except FitError as error:
        assert "\n" not in str(error)


@settings(max_examples=40, deadline=None, derandomize=True, database=None,
          suppress_health_check=list(HealthCheck))
@given(where=st.floats(0.0, 0.999), data=st.binary(max_size=16))
def test_corrupted_bag_bytes_are_one_line_never_a_traceback(good_bag, where, data):
    """OverflowError, MemoryError, ReaderError and struct.error came out of rosbags."""
    assert_read_or_refused(corrupted(good_bag, where, data))


def test_a_damaged_message_definition_is_one_short_line(good_bag):
    """The hunt's find: a byte of the schema in the MCAP zeroed ("Header head\\x00r"):
    rosbags quoted the whole definition over 16 lines."""
    copy = Path(f"{good_bag}_{next(COPIES)}")
    shutil.copytree(good_bag, copy)
    (mcap,) = copy.glob("*.mcap")
    raw = mcap.read_bytes()
    at = raw.rindex(b"std_msgs/Header header") + len(b"std_msgs/Header head")   # summary
    mcap.write_bytes(raw[:at] + b"\x00" + raw[at + 1:])
    with pytest.raises(FitError) as refused:
        read_recording(str(copy), JOINT_NAMES)
    assert "\n" not in str(refused.value) and len(str(refused.value)) < 250
    assert "Could not parse" in str(refused.value)


@pytest.mark.hunt
@settings(max_examples=2000, deadline=None, derandomize=True, database=None,
          suppress_health_check=list(HealthCheck))
@given(where=st.floats(0.0, 0.999), data=st.binary(max_size=64))
def test_hunt_corrupted_bag_bytes(good_bag, where, data):
    assert_read_or_refused(corrupted(good_bag, where, data))


def test_a_bag_without_its_metadata_and_a_csv_with_a_byte_order_mark(tmp_path, good_bag):
    """Read as "cannot write", and "no column t"."""
    bare = tmp_path / "bare"
    shutil.copytree(good_bag, bare)
    (bare / "metadata.yaml").unlink()
    with pytest.raises(FitError, match="holds no metadata.yaml"):
        read_recording(str(bare), JOINT_NAMES)
    path = tmp_path / "bom.csv"
    path.write_text(" t , q1,q2,qd1,qd2,tau1,tau2\n" + "".join(
        ",".join(map(str, r)) + "\n" for r in rows(recording(1.0)[0])), encoding="utf-8-sig")
    assert len(read_recording(str(path), JOINT_NAMES)) == len(recording(1.0)[0])


def listening(answer):
    """A server on a free port that accepts and answers `answer` (bytes) or nothing."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(8)
    kept = []

    def serve():
        while True:
            connection, _ = server.accept()
            kept.append(connection)
            if answer:
                connection.recv(65536)
                connection.sendall(answer)

    threading.Thread(target=serve, daemon=True).start()
    return f"tcp://127.0.0.1:{server.getsockname()[1]}"


@pytest.mark.parametrize("answer, expected", [
    (b"HTTP/1.1 200 OK\r\nContent-Length: 5\r\n\r\nhello", "not a Dask scheduler"),
    (b"", "no answer in 1 s")])
def test_a_scheduler_that_is_no_dask_scheduler_is_one_line(capsys, short_bag, monkeypatch,
                                                            answer, expected):
    """Dask's dashboard port: "Unable to allocate 3.07 EiB"; a silent server: no end."""
    pytest.importorskip("distributed")
    monkeypatch.setattr(command, "CONNECT_SECONDS", 1.0)
    monkeypatch.setattr(command, "CONNECT_GRACE", 2.0)
    line = fit(capsys, short_bag, *base_args(), "--free", "damping", "--scheduler",
               listening(answer), code=2)
    assert expected in line


def test_workers_are_never_more_than_the_cpus(capsys, monkeypatch):
    """--workers 16 on 2 CPUs started 16 processes (2.9 GB)."""
    monkeypatch.setattr(command.os, "cpu_count", lambda: 2)
    from arm_sim_ros.tools.cli import build_parser
    args = build_parser().parse_args(["fit", "x.csv", "--free", "damping", "--workers", "16"])
    command.checked_args(args)
    assert args.workers == 2 and "--workers 16: 2 processes, one per CPU" in (
        capsys.readouterr().err)
