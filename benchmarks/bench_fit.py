"""`arm-sim fit` on the full done-when case: what it recovers and how long it takes.

A recording made by a different simulator (test/tools/test_fit_reference.py: scipy DOP853 on
separately written equations with located friction events), 10 s at 500 Hz, Gaussian noise
1e-4 rad and 1e-3 rad/s, a multi-sine; hidden damping, Coulomb friction, rotor inertia
(through 50:1 and 30:1 gears) and payload mass, all four keys (seven numbers) freed from
wrong starts. Printed: each parameter's truth, fit, standard error, error in % and in
standard errors; the validation error in units of the noise; the wall time (the recording
written as a bag, read, fitted with the default multi-start on --workers processes) and
the time to make the reference recording. Timings are wall-clock on whatever else the
machine runs: noisy.

    python benchmarks/bench_fit.py [--workers N] [--duration S]
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from contextlib import redirect_stdout
from io import StringIO
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "test"))

from tools.test_fit import TRUTH, WRONG, base_args, write_bag  # noqa: E402
from tools.test_fit_reference import recording  # noqa: E402

from arm_sim_ros.tools import cli  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--duration", type=float, default=10.0)
    parser.add_argument("--starts", type=int, default=2)
    args = parser.parse_args()
    started = time.perf_counter()
    rec, _ = recording(args.duration)
    made = time.perf_counter() - started
    with tempfile.TemporaryDirectory() as tmp:
        bag = write_bag(Path(tmp) / "hidden", rec)
        moved = {k.replace(".", "__"): v for k, v in WRONG.items()}
        out = StringIO()
        started = time.perf_counter()
        with redirect_stdout(out):
            status = cli.main(["fit", bag, *base_args(**moved), "--free", ",".join(WRONG),
                               "--workers", str(args.workers), "--starts", str(args.starts),
                               "--json"])
        seconds = time.perf_counter() - started
    outcome = json.loads(out.getvalue())
    print(f"recording: {args.duration:g} s at 500 Hz by DOP853 (made in {made:.1f} s); exit "
          f"status {status}")
    print(f"{'parameter':24s} {'truth':>10s} {'fitted':>12s} {'s.e.':>9s} {'error %':>8s} "
          f"{'error/s.e.':>10s}")
    for p in outcome["parameters"]:
        truth = TRUTH[p["key"]]
        error = p["value"] - truth
        print(f"{p['key']:24s} {truth:10.4g} {p['value']:12.6g} {p['se']:9.2g} "
              f"{100 * error / truth:8.3f} {error / p['se']:10.2f}")
    v = outcome["validation"]
    print(f"validation ({v['seconds']:.3g} s held out): RMS = "
          + ", ".join(f"{m:.3f}" for m in v["noise_multiple"]) + " x the noise (q1, q2, qd1, qd2)")
    print(f"starts: " + ", ".join(f"cost {s['cost']:.6g} ({s['evaluations']} evaluations)"
                                  for s in outcome["starts"]))
    print(f"fit time: {seconds:.1f} s wall ({args.starts} starts on {args.workers} workers; "
          f"the fit's own clock {outcome['seconds']:.1f} s)")


if __name__ == "__main__":
    main()
