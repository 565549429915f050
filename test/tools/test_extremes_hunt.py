"""Hunts of issue 47 (run by hand: `scripts/test -m hunt -s test/tools/test_extremes_hunt.py`):

- extreme values of every numeric scene key (0, ±1e-310, ±1e308, ±inf, NaN, huge and
  64-bit integers, negatives, the largest angle ...), each on presets that use the key:
  offline (`arm-sim run` with --csv and --json; --rerun and --bag where the value is
  huge), at the node's start and set live. Each case gives one clear line or a run; no
  traceback, no output holding a number that is not finite, no node stamp standing still,
  and one rule: a value the command line refuses the node refuses at start, and the other
  way round (but for the node's own budget of sub-steps per tick and keys it does not take);
- random bytes in every kind of kernel-cache file (the module .py, numba's .nbi and .nbc),
  of a smooth and a switching scene, then `arm-sim run` and the node in processes of their
  own: the right answer, at most one line saying what was set aside, and a quiet run after.

Each prints its counts and its time (the counts go in the issue's note)."""
from __future__ import annotations

import contextlib
import io
import json
import logging
import math
import os
import shutil
import subprocess
import sys
import time

import numpy as np
import pytest

from arm_sim_ros.node import core as node_core
from arm_sim_ros.node.params import parameters as node_params
from arm_sim_ros.physics.scene import FIELD_KINDS, MAPPINGS, SceneError, load_scene, parse_value
from arm_sim_ros.tools import cli

from tools.finite_outputs import bag_places, csv_places, json_places, rrd_places

VALUES = ["0", "1e-310", "-1e-310", "5e-324", "1e-300", "1e308", "-1e308", "inf", "-inf",
          "nan", "1" + "0" * 400, "9223372036854775807", "9223372036854775808", "-1", "1e6",
          "-1e6", "1e154", "1e300"]
HUGE = ("1e308", "-1e308", "1e154", "1e300")      # these also write --rerun and --bag
# Presets that use each effect's keys; a scene's own keys on presets with a policy of each
# kind (none, gravity compensation, a servo, a constant torque)
EFFECT_SCENES = {"springs": ["springs_oscillation"], "payload": ["payload_release"],
                 "motors": ["geared_arm", "motor_windings_hold"],
                 "effort_limits": ["effort_limited_hold"],
                 "controller_model": ["wrong_payload_model"], "friction": ["stick_slip"],
                 "joint_limits": ["compliant_limit", "limit_impact"], "servo": ["servo_hold"],
                 "sensors": ["release", "servo_hold"]}
SCENES = ["release", "moving_gravity_compensation", "servo_hold", "shoulder_torque_no_gravity"]
STEPS = 8
# The node's own refusals, not a scene's: its budget of sub-steps per tick, keys it does
# not take as parameters (set-points come on topics)
NODE_ONLY = ("max_substeps", "unknown parameter", "start-only")


def numeric_keys():
    for name, kind in FIELD_KINDS.items():
        if kind in ("float", "int", "pair", "float_or_pair", "pair_or_none") and name != "duration":
            yield name, kind, SCENES
    for effect, parameters in MAPPINGS.items():
        for p in parameters.parameters:
            if p.kind in ("float", "int", "pair"):
                yield f"{effect}.{p.name}", p.kind, EFFECT_SCENES[effect]


def texts(kind: str, value: str) -> list[str]:
    if kind in ("float", "int"):
        return [value]
    return [f"{value},{value}", f"0.5,{value}"] + ([value] if kind == "float_or_pair" else [])


class Tally:
    def __init__(self):
        self.cases = self.tracebacks = self.nonfinite = self.stood_still = 0
        self.disagreements = self.many_lines = 0
        self.found = []

    def problem(self, kind: str, case, detail) -> None:
        setattr(self, kind, getattr(self, kind) + 1)
        self.found.append(f"{kind}: {case}: {str(detail)[:300]}")


def offline(tally, case, scene, sets, folder, huge: bool) -> bool | None:
    """`arm-sim run` of `scene` with `sets`: True refused in one line, False ran (its
    outputs checked), None a traceback."""
    h = load_scene(scene).step_size
    for text in sets:
        if text.startswith("step_size="):
            with contextlib.suppress(ValueError):
                h = float(text.partition("=")[2])
    duration = repr(STEPS * h) if 0 < h <= 0.01 else "0.08"
    outputs = {"--csv": folder / "run.csv"}
    if huge:
        outputs |= {"--rerun": folder / "run.rrd", "--bag": folder / "bag"}
    argv = ["run", "--scene", scene, "--duration", duration, "--json", "--force"]
    argv += [str(x) for option, path in outputs.items() for x in (option, path)]
    argv += [x for text in sets for x in ("--set", text)]
    out, err = io.StringIO(), io.StringIO()
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            code = cli.main(argv)
    except Exception as error:         # a traceback a person would have met
        tally.problem("tracebacks", case, f"offline {type(error).__name__}: {error}")
        return None
    if code == 2:
        if err.getvalue().count("\n") != 1:
            tally.problem("many_lines", case, err.getvalue())
        return True
    places = csv_places(outputs["--csv"]) | json_places(json.loads(out.getvalue()))
    if huge:
        places |= rrd_places(outputs["--rerun"]) | bag_places(outputs["--bag"])
    for path in outputs.values():
        shutil.rmtree(path) if path.is_dir() else path.unlink(missing_ok=True)
    if places:
        tally.problem("nonfinite", case, f"offline {sorted(places)}")
    return False


def finite(data) -> bool:
    return all(math.isfinite(v) for part in (data, data.truth) if part is not None
               for v in part.position + part.velocity + part.effort)


def ticks(tally, case, core, where: str) -> None:
    """Four ticks: finite messages, stamps that move."""
    stamps = []
    for _ in range(4):
        data = core.tick()
        stamps.append(data.stamp_ns)
        if not finite(data):
            tally.problem("nonfinite", case, f"{where}: {data}")
            return
    if not all(b > a for a, b in zip(stamps, stamps[1:])):
        tally.problem("stood_still", case, f"{where}: stamps {stamps}")


def node(tally, case, scene, key, sets) -> bool | None:
    """The node started with the value (True refused, False ran, None: not the node's to
    judge), then the value set live on a node started without it."""
    try:
        values = {k: parse_value(k, t) for k, _, t in (s.partition("=") for s in sets)}
    except SceneError:
        return True                    # refused as text, as the command line refuses it
    values = {k: list(v) if isinstance(v, tuple) else v for k, v in values.items()}
    log = logging.getLogger("hunt")
    try:
        core = node_core.ArmSimCore(node_params.resolve_parameters({"scene": scene} | values),
                                    log)
        ticks(tally, case, core, "start")
        started = False
    except node_params.ParameterRefused as refused:
        started = None if any(w in refused.reason for w in NODE_ONLY) else True
    except Exception as error:
        tally.problem("tracebacks", case, f"node start {type(error).__name__}: {error}")
        return None
    try:
        core = node_core.ArmSimCore(node_params.resolve_parameters(
            {"scene": scene} | {k: v for k, v in values.items() if k != key}), log)
        core.tick()
        before = (core.config, core.sim.state, core.sim.steps)
        try:
            core.set_parameters({key: values[key]})
        except node_params.ParameterRefused as refused:
            if (core.config, core.sim.state, core.sim.steps) != before:
                tally.problem("disagreements", case, "a live refusal changed the node")
            if started is False and not any(w in refused.reason for w in NODE_ONLY):
                tally.problem("disagreements", case, f"started, refused live: {refused}")
        else:
            ticks(tally, case, core, "live")
    except Exception as error:
        tally.problem("tracebacks", case, f"node live {type(error).__name__}: {error}")
    return started


@pytest.mark.hunt
def test_extreme_values_of_every_numeric_scene_key_hunt(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("ARM_SIM_COMPILED", "0")     # the rule is the physics': one path is
    logging.disable(logging.CRITICAL)               # enough (the compiled one: the same)
    tally, started = Tally(), time.perf_counter()
    try:
        for key, kind, scenes in numeric_keys():
            for scene in scenes:
                for value in VALUES:
                    for text in texts(kind, value):
                        extra = [["sensors.velocity=differences"]] if key.startswith("sensors.") \
                            and key != "sensors.velocity_noise" else [[]]
                        for sets in ([f"{key}={text}"] + e for e in [[]] + extra):
                            case = f"{scene} {' '.join(sets)}"
                            tally.cases += 1
                            refused = offline(tally, case, scene, sets, tmp_path,
                                              value in HUGE)
                            at_start = node(tally, case, scene, key, sets)
                            if None not in (refused, at_start) and refused != at_start:
                                tally.problem("disagreements", case,
                                              f"offline refused {refused}, node {at_start}")
    finally:
        logging.disable(logging.NOTSET)
    seconds = time.perf_counter() - started
    with capsys.disabled():
        print(f"\nextreme values: {tally.cases} cases, {tally.tracebacks} tracebacks, "
              f"{tally.nonfinite} non-finite outputs, {tally.stood_still} stamps standing "
              f"still, {tally.disagreements} disagreements, {tally.many_lines} refusals of "
              f"more than one line; {seconds:.0f} s")
        for line in tally.found[:40]:
            print("  " + line)
    assert not tally.found


# -- random bytes in the kernel cache -----------------------------------------------------

ARM_SIM = [sys.executable, "-m", "arm_sim_ros.tools.cli"]
DAMAGES = ("truncated", "random bytes", "random length", "flipped bytes", "empty", "appended")


def damaged(data: bytes, how: str, rng) -> bytes:
    if how == "truncated":
        return data[:int(rng.integers(0, max(len(data), 1)))]
    if how == "random bytes":
        return rng.integers(0, 256, len(data), dtype=np.uint8).tobytes()
    if how == "random length":
        return rng.integers(0, 256, int(rng.integers(1, 4096)), dtype=np.uint8).tobytes()
    if how == "flipped bytes":
        out = bytearray(data)
        for at in rng.integers(0, len(out), int(rng.integers(1, 9))):
            out[at] ^= int(rng.integers(1, 256))
        return bytes(out)
    if how == "empty":
        return b""
    return data + rng.integers(0, 256, int(rng.integers(1, 512)), dtype=np.uint8).tobytes()


def run(argv, cache, env=None, timeout=900):
    environment = {k: v for k, v in os.environ.items() if k != "ARM_SIM_COMPILED"}
    done = subprocess.run(argv, env=environment | {"ARM_SIM_CACHE": str(cache)} | (env or {}),
                          capture_output=True, text=True, timeout=timeout)
    return done.returncode, done.stdout, done.stderr


def cache_files(cache, kind: str) -> list:
    return sorted(cache.glob("arm_sim_kernel_*.py") if kind == "py"
                  else (cache / "__pycache__").glob(f"*.{kind}"))


@pytest.mark.hunt
def test_random_bytes_in_every_kind_of_kernel_cache_file_hunt(tmp_path, capsys):
    pytest.importorskip("numba")
    from node.test_node_dds import CONFIG
    node_env = {"ROS_DOMAIN_ID": "97", "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
                "CYCLONEDDS_URI": CONFIG}
    # every damage on a smooth scene; the three that break a file's inside on a switching
    # scene (a module a mode) and on the node (the issue's: its exit 2 blamed the physics)
    inside = ("random bytes", "truncated", "flipped bytes")
    commands = {
        "run release": (ARM_SIM + ["run", "--scene", "release", "--duration", "0.2", "--json"],
                        DAMAGES),
        "run stick_slip": (ARM_SIM + ["run", "--scene", "stick_slip", "--duration", "0.5",
                                      "--json"], inside),
        "node release": ([sys.executable, "-m", "arm_sim_ros.node.main", "--transport", "dds",
                          "--duration", "0.1", "--quiet", "--ros-args", "-p",
                          "real_time_factor:=0.0"], inside)}
    rng = np.random.default_rng(47)
    cases = tracebacks = wrong = said_wrong = 0
    found, started = [], time.perf_counter()
    for name, (argv, damages) in commands.items():
        env = node_env if name.startswith("node") else None
        good = tmp_path / f"good {name}"
        code, expected, err = run(argv, good, env)           # the first compile, kept
        assert code == 0, err
        for kind in ("py", "nbi", "nbc"):
            for how in damages:
                cases += 1
                cache = tmp_path / f"{name} {kind} {how}"
                shutil.copytree(good, cache)
                files = cache_files(cache, kind)
                chosen = rng.choice(len(files), int(rng.integers(1, len(files) + 1)),
                                    replace=False)
                for i in chosen:
                    files[i].write_bytes(damaged(files[i].read_bytes(), how, rng))
                for attempt in ("damaged", "after"):
                    code, out, err = run(argv, cache, env)
                    lines = [line for line in err.splitlines() if "kernel cache" in line]
                    case = f"{name}, {kind} {how} ({len(chosen)} of {len(files)}), {attempt}"
                    if code != 0 or "Traceback" in err:
                        tracebacks += 1
                        found.append(f"{case}: exit {code}: {err[-400:]}")
                    elif not name.startswith("node") and out != expected:
                        wrong += 1
                        found.append(f"{case}: another answer")
                    elif len(lines) > (1 if attempt == "damaged" else 0) or (
                            lines and "set aside" not in lines[0]):
                        said_wrong += 1
                        found.append(f"{case}: said {lines}")
                shutil.rmtree(cache)
    seconds = time.perf_counter() - started
    with capsys.disabled():
        print(f"\nkernel cache: {cases} damaged caches ({2 * cases} runs), {tracebacks} "
              f"tracebacks or failed runs, {wrong} other answers, {said_wrong} wrong lines; "
              f"{seconds:.0f} s")
        for line in found[:40]:
            print("  " + line)
    assert not found
