"""`--vary KEY=SPEC` and the samples it makes: values read as --set reads them, grids in
product order, draws that depend on (seed, index) alone, blocks that depend on the count
alone, and every bad key or SPEC refused in one line (exit 2), as --set refuses."""
from math import radians

import numpy as np
import pytest

from arm_sim_ros.physics.scene import SceneError, load_scene
from arm_sim_ros.tools import cli
from arm_sim_ros.tools.sweep.api import make_sweep
from arm_sim_ros.tools.sweep.plan import Plan
from arm_sim_ros.tools.sweep.spec import parse_vary


def test_lists_grids_and_ranges_hold_the_values_they_name():
    assert parse_vary("payload.mass=0.2,0.5,1.0").values == (0.2, 0.5, 1.0)
    assert parse_vary("integrator=rk4,exponential_rk4").values == ("rk4", "exponential_rk4")
    assert parse_vary("step_size=lin:0.001:0.004:4").values == pytest.approx(
        (0.001, 0.002, 0.003, 0.004))
    assert parse_vary("springs.stiffness=log:1:1000:4").values == pytest.approx((1, 10, 100, 1000))
    assert parse_vary("sensors.seed=range:0:10:3").values == (0, 3, 6, 9)
    assert parse_vary("sensors.seed=9223372036854775807").values == (2 ** 63 - 1,)
    assert parse_vary("sensors.seed=integers:0:4294967295").law == ("integers", (0, 2 ** 32 - 1))


def test_a_pair_key_takes_pairs_between_semicolons_one_number_for_both_or_one_joint():
    pairs = parse_vary("initial_positions=0,0;90deg,0")
    assert pairs.values == ((0.0, 0.0), (radians(90), 0.0))
    assert pairs.columns == ("initial_positions[0]", "initial_positions[1]")
    both = parse_vary("friction.coulomb=0.1;0.2")
    assert both.values == (0.1, 0.2) and both.columns == ("friction.coulomb",)
    assert parse_vary("springs.stiffness=20,5").values == ((20.0, 5.0),)     # --set's pair
    one = parse_vary("friction.coulomb[1]=0.1,0.3")
    assert (one.field, one.joint, one.values) == ("friction.coulomb", 1, (0.1, 0.3))
    base = load_scene("stick_slip")
    plan = Plan.make([one], None, 0)
    scene = plan.scene(base, plan.values(1))
    assert scene.friction["coulomb"] == (base.friction["coulomb"][0], 0.3)
    plan = Plan.make([parse_vary("springs.stiffness=50")], None, 0)
    assert plan.scene(load_scene("springs_oscillation"), plan.values(0)).springs["stiffness"] \
        == (50.0, 50.0)


def test_grids_form_their_product_the_first_key_varying_slowest():
    plan = Plan.make([parse_vary("payload.mass=0.1,0.2"), parse_vary("gravity=1,2,3")], None, 0)
    assert plan.count == 6 and plan.draws == 1
    assert [plan.values(i) for i in range(6)] == [(0.1, 1.0), (0.1, 2.0), (0.1, 3.0),
                                                  (0.2, 1.0), (0.2, 2.0), (0.2, 3.0)]


def test_a_draw_depends_on_the_seed_and_the_index_alone():
    varies = [parse_vary("payload.mass=0.1,0.2"), parse_vary("friction.coulomb=uniform:0:1"),
              parse_vary("gravity=normal:9.81:0.1"), parse_vary("sensors.seed=integers:0:99")]
    plan = Plan.make(varies, 5, 7)
    assert plan.count == 10 and plan.draws == 5
    first = [plan.values(i) for i in range(plan.count)]
    assert [plan.values(i) for i in reversed(range(plan.count))] == first[::-1]
    rng = np.random.Generator(np.random.Philox(np.random.SeedSequence([7, 6])))
    assert first[6] == (0.2, rng.uniform(0, 1), rng.normal(9.81, 0.1),
                        int(rng.integers(0, 99, endpoint=True)))
    assert Plan.make(varies, 5, 8).values(6) != first[6]
    assert len({v[1] for v in first}) == 10                 # every sample its own draw
    median = np.median([Plan.make([parse_vary("payload.mass=lognormal:0.5:0.2")], 400, 0)
                        .values(i)[0] for i in range(400)])
    assert median == pytest.approx(0.5, rel=0.05)


def test_blocks_depend_on_the_count_alone_and_cover_it_once():
    plan = Plan.make([parse_vary("gravity=uniform:0:10")], 1000, 0)
    blocks = plan.blocks()
    assert blocks[0] == (0, 16) and blocks[-1][1] == 1000
    assert [i for first, stop in blocks for i in range(first, stop)] == list(range(1000))


@pytest.mark.parametrize("vary, words", [
    ("paylod.mass=1", "unknown scene key 'paylod.mass'; did you mean"),
    ("friction.colomb=0.1", "not a key of friction; did you mean 'friction.coulomb'"),
    ("payload.mass=-1", "payload.mass = -1 is impossible"),
    ("payload.mass=lin:1:2", "lin:A:B:N takes two numbers and a count"),
    ("payload.mass=log:0:1:5", "log:A:B:N needs A and B of one sign"),
    ("payload.mass=uniform:1:0", "uniform:A:B needs A <= B"),
    ("payload.mass=normal:1:-1", "spread -1 must not be negative"),
    ("payload.mass=gauss:1:1", "gauss: is no SPEC"),
    ("payload.mass=0.1,,0.2", "an empty value"),
    ("payload.mass=abc", "malformed"),
    ("integrator=lin:1:2:3", "give them as a list"),
    ("sensors.seed=uniform:0:9", "sensors.seed takes int values: give them as a list (a,b or "
                                 "a;b), range: or integers:, not uniform:"),
    ("integrator=rk5", "integrator 'rk5' is unknown"),
    ("gravity[0]=1", "gravity is not a per-joint key"),
    ("step_size=lin:0.001:0.003:3", "not a whole number of steps"),
    ("friction=1", "sets one parameter at a time"),
    ("gravity", "not of the form KEY=SPEC"),
])
def test_a_bad_key_or_spec_is_one_line_and_exit_2(capsys, tmp_path, vary, words):
    code = cli.main(["sweep", "release", "--vary", vary, "--duration", "0.01",
                     "-o", str(tmp_path / "x.csv")])
    err = capsys.readouterr().err
    assert code == 2 and words in err and err.count("\n") == 1, err
    assert err.startswith(f"arm-sim: error: --vary {vary}")


def test_the_sweep_refuses_what_run_refuses_in_the_same_words(capsys, tmp_path):
    code = cli.main(["run", "--set", "paylod.mass=1"])
    said = capsys.readouterr().err.split("error: ")[1]
    assert code == 2
    code = cli.main(["sweep", "release", "--vary", "paylod.mass=1", "-o", str(tmp_path / "x.csv")])
    assert code == 2 and capsys.readouterr().err.split("paylod.mass=1: ")[1] == said


def test_samples_without_a_distribution_and_a_key_twice_are_refused():
    with pytest.raises(SceneError, match="no --vary draws from a distribution"):
        make_sweep(load_scene(), ["gravity=1,2"], samples=5)
    with pytest.raises(SceneError, match="set the same value"):
        make_sweep(load_scene(), ["friction.coulomb=0.1", "friction.coulomb[0]=0.2"])
    with pytest.raises(SceneError, match="metrics"):
        make_sweep(load_scene(), ["gravity=1"], metrics="settling")


def test_a_sweep_turns_the_estimate_off_unless_asked():
    assert make_sweep(load_scene(), ["gravity=1"]).base.estimate == "off"
    assert make_sweep(load_scene(), ["gravity=1"], estimate=None).base.estimate == "global"
    assert make_sweep(load_scene(), ["tolerance=1e-4"]).base.estimate == "global"


def test_a_plot_of_no_column_is_refused_before_any_work(capsys, tmp_path):
    out = tmp_path / "x.csv"
    code = cli.main(["sweep", "release", "--vary", "gravity=1", "--plot", "settle_tme_1",
                     "-o", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and "no column 'settle_tme_1'; did you mean 'settle_time_1'" in err
    assert not out.exists()
