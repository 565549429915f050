"""Every file `arm-sim run` writes is claimed exclusively before the run (as --bag's
directory is by its mkdir): of two runs naming the same --csv or --rerun, the second is
refused in one line and the first's file is left whole."""
import struct

import pytest

from arm_sim_ros import outputs
from arm_sim_ros.tools import cli
from arm_sim_ros.usage import UsageError


@pytest.mark.parametrize("option, name", [("--csv", "run.csv"), ("--rerun", "run.rrd")])
def test_a_second_run_on_the_same_file_is_refused_in_one_line(tmp_path, capsys, monkeypatch,
                                                              option, name):
    path = tmp_path / name
    checked = cli.check_output

    def other_run_claims_it_meanwhile(*args, **kwargs):
        result = checked(*args, **kwargs)   # both runs found the name free...
        path.write_bytes(b"the other run's rows\n")   # ...and the other one opened it first
        return result

    monkeypatch.setattr(cli, "check_output", other_run_claims_it_meanwhile)
    code = cli.main(["run", "--scene", "release", "--duration", "0.1", option, str(path)])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "another run" in err
    assert path.read_bytes() == b"the other run's rows\n"


def test_a_claim_is_exclusive_and_a_device_is_never_claimed(tmp_path):
    path = tmp_path / "a.csv"
    assert outputs.claim_output(str(path), "--csv") and path.read_bytes() == b""
    with pytest.raises(UsageError, match="another run"):
        outputs.claim_output(str(path), "--csv")
    assert not outputs.claim_output("/dev/null", "--csv")


def test_a_run_refused_after_the_claim_leaves_no_empty_file(tmp_path, capsys):
    csv_path, bag = tmp_path / "run.csv", tmp_path / "bag"
    # a publish rate that does not divide the step is refused by the bag, after the claim
    code = cli.main(["run", "--scene", "release", "--duration", "0.1", "--csv", str(csv_path),
                     "--bag", str(bag), "--publish-rate", "33"])
    assert code == 2 and not csv_path.exists()


def test_a_full_disk_under_rerun_ends_in_an_error_a_nonzero_exit_and_a_readable_file(tmp_path):
    """rerun only logs a write the disk refuses; the run checks the file at its end, cuts it
    back to its whole messages and says so (a file-size limit stands in for a full disk)."""
    import resource
    import subprocess
    import sys

    from rerun.chunk import RrdReader

    path = tmp_path / "run.rrd"

    def small_disk():
        resource.setrlimit(resource.RLIMIT_FSIZE, (300_000, 300_000))

    run = subprocess.run([sys.executable, "-m", "arm_sim_ros.tools.cli", "run", "--duration", "30",
                          "--rerun", str(path)], preexec_fn=small_disk, capture_output=True,
                         text=True, timeout=120)
    ours = [line for line in run.stderr.splitlines() if line.startswith("arm-sim: error")]
    assert run.returncode == 2 and len(ours) == 1 and "cut back" in ours[0]
    assert "Traceback" not in run.stderr
    entities = {chunk.entity_path for chunk in RrdReader(str(path)).stream()}
    assert "/energy/balance_residual" in entities   # what fit reads back


def test_a_nodes_recording_keeps_no_manifest_in_memory_and_is_still_checked(tmp_path):
    """rerun keeps ~1 kB per chunk for the footer's manifest until the file closes: a node
    (hours of recording) writes none. Its file then has no end marker: whole messages are
    complete, and a file cut mid-message is cut back and said, as with a footer."""
    from arm_sim_ros.physics.scene import load_scene
    from arm_sim_ros.physics.simulator import Simulator
    from arm_sim_ros.recording.rrd import sinks
    from arm_sim_ros.recording.rrd.telemetry import make_recorder
    from recording.test_telemetry import read_back

    sim, path = Simulator(load_scene("release")), tmp_path / "node.rrd"
    recorder = make_recorder(path=str(path))
    recorder.for_node(0)
    recorder.start(sim)
    for _ in range(50):
        sim.step()
        recorder.step(sim)
    recorder.finish(sim)
    data = path.read_bytes()
    kinds, position = [], sinks.RRD_HEADER
    while position < len(data):
        kind, length = struct.unpack_from("<QQ", data, position)
        kinds.append(kind)
        position += 16 + length
    assert position == len(data) and sinks.RRD_END not in kinds      # no footer, whole
    assert len(read_back(path)["joints/angle"]["Scalars:scalars"]) == 51
    path.write_bytes(data[:-5])                                       # cut mid-message
    with pytest.raises(UsageError, match="cut back"):
        sinks.check_rrd_file(path, footer=False)
    assert path.stat().st_size == len(data) - 16 - length and read_back(path)


def test_text_lines_sent_without_rows_are_each_recorded(tmp_path):
    """A batch of event lines and no steps (a live change between ticks) puts each line at
    the last row sent; rerun refused the batch before (one time index for two lines)."""
    import warnings

    from arm_sim_ros.physics.scene import load_scene
    from arm_sim_ros.physics.simulator import Simulator
    from arm_sim_ros.recording.rrd.telemetry import make_recorder
    from recording.test_telemetry import read_back

    sim, path = Simulator(load_scene("release")), tmp_path / "lines.rrd"
    recorder = make_recorder(path=str(path))
    recorder.start(sim)
    recorder.flush(force=True)
    recorder.event("first line")
    recorder.event("second line")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        recorder.flush(force=True)
        recorder.finish(sim)
    texts = read_back(path)["events"]["TextLog:text"]
    assert "first line" in texts and "second line" in texts
