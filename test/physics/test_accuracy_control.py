"""Issue 22: accuracy control you can trust, at the price it should cost.

The sub-step count follows the error estimate both ways (a PI step-size controller on the
sub-step, physics/trust/accuracy.py), the stability plan is its floor, `max_substeps` its
ceiling (said once when the tolerance cannot be met), and the divergence guard is scaled
by the energy in play, not by where V = 0 (physics/trust/guard.py).
"""
import pytest

from arm_sim_ros.physics.stepping.stability import substepping
from arm_sim_ros.physics.trust import guard
from arm_sim_ros.physics.trust.accuracy import DEFAULT_MAX_SUBSTEPS, THREE_LEVELS
from arm_sim_ros.physics.trust.controller import proposed
from arm_sim_ros.physics.scene import Scene, SceneError, load_scene
from arm_sim_ros.physics.simulator import Simulator
from arm_sim_ros.tools import cli


def counts_over(sim, duration):
    """The free-motion sub-step count after every step."""
    counts = []
    sim.run(duration, lambda s: counts.append(s.accuracy.substeps))
    return counts


def test_the_controller_asks_for_fewer_sub_steps_when_the_error_falls_well_below():
    # order 4: a step measured at 1/16 of the aim could take sub-steps twice as long; the
    # controller's integral gain (0.7) moves 16^(0.7/4) = 1.62x of the way: 8 -> ceil(4.9)
    assert proposed(8, 1.0 / 16.0, 1.0 / 16.0, 4, 1, 1000) == 5
    assert proposed(8, 4.0, 4.0, 4, 1, 1000) > 8          # and more when it rises
    assert proposed(8, 1e-9, 1e-9, 4, 1, 1000) == 4       # growth of a sub-step bounded: 2x
    assert proposed(8, 1e-9, 1e-9, 4, 6, 1000) == 6       # never under the floor
    assert proposed(8, 1e9, 1e9, 4, 1, 50) == 50          # never over the cap
    assert proposed(8, 0.8, 0.8, 4, 1, 1000) == 8         # no dithering near the aim


def test_sub_steps_come_back_down_when_a_fast_motion_slows():
    """A 100 rad/s spin braked by damping: the count the spin needs is given back."""
    scene = Scene(initial_positions=(0.0, 0.5), initial_velocities=(100.0, 0.0), gravity=0.0,
                  damping=0.5, step_size=0.01)
    sim = Simulator(scene)
    counts = counts_over(sim, 10.0)
    assert max(counts) >= 4
    assert counts[-1] <= max(counts) / 2
    assert sim.substeps_taken < len(counts) * max(counts) / 2   # the ratchet would pay it all


def test_the_stability_plan_is_a_floor_not_a_ratchet():
    scene = load_scene("damped_release").replace(damping=500.0, step_size=0.05,
                                                 initial_velocities=(4.0, -6.0))
    sim = Simulator(scene)
    assert sim.substeps > 1
    counts = counts_over(sim, 2.0)
    assert min(counts) >= sim.substeps


def test_a_cap_the_tolerance_cannot_meet_is_said_once_with_the_error_reached():
    sim = Simulator(load_scene("release").replace(tolerance=1e-9, max_substeps=3))
    counts = counts_over(sim, 2.0)
    assert max(counts) == 3
    said = [e.message for e in sim.events if "not met" in e.message]
    assert len(said) == 1
    assert "at the cap of 3 sub-steps" in said[0] and "per s" in said[0]


def test_max_substeps_is_a_whole_number_within_reach():
    for bad in (0, 2.5, 1e9, -3):
        with pytest.raises(SceneError, match="max_substeps"):
            load_scene("release").replace(max_substeps=bad)
    assert load_scene("release").max_substeps == DEFAULT_MAX_SUBSTEPS


def test_a_step_that_misses_the_tolerance_is_taken_again():
    """After a check that misses, the error the step was taken with meets the tolerance."""
    sim = Simulator(load_scene("release").replace(tolerance=1e-7))
    sim.run(2.0)
    h = sim.step_size
    assert sim.substeps_taken > 0
    assert sim.error_estimate <= 1e-7 * h * (1 + abs(sim.state[2]) + abs(sim.state[3]))


@pytest.mark.parametrize("name", ["stick_slip", "limit_impact", "compliant_limit"])
def test_tightening_the_tolerance_keeps_buying_accuracy_on_switching_scenes(name):
    """Against the same scene at h/64 and a tolerance far tighter (the independent check is
    in the study); the error falls as the tolerance tightens."""
    scene = load_scene(name).replace(duration=1.0)
    fine = Simulator(scene.replace(step_size=scene.step_size / 64, tolerance=1e-10))
    fine.run(1.0)
    errors = []
    for tolerance in (1e-4, 1e-6):
        sim = Simulator(scene.replace(tolerance=tolerance))
        sim.run(1.0)
        errors.append(max(abs(a - b) for a, b in zip(sim.state[:4], fine.state[:4])))
    assert errors[1] < errors[0] / 5, errors


def test_contacts_and_free_flight_are_controlled_apart():
    """An undamped arm bouncing on stiff compliant stops: the fine steps a contact needs
    are not paid in the flight between contacts."""
    scene = load_scene("compliant_limit").replace(
        **{"joint_limits.stiffness": 1e7, "joint_limits.damping": 0.0}, step_size=0.05)
    sim = Simulator(scene)
    counts = counts_over(sim, 10.0)
    assert sim.switching.substeps_for(0.05, True) >= sim.switching.contact_floor(0.05) > 100
    assert max(counts) < 50
    assert sim.fault is None


def test_semi_implicit_euler_at_mujocos_step_runs_the_release_to_the_end():
    """Stable, never called diverged (the guard's scale is the energy in play, ~20 J here, not
    1 + |E(0)| = 1 J because the arm starts horizontal). Its energy error is not bounded on
    this chaotic motion: checked at every state, 27 % of the energy in play at t = 6.33 s
    (69 % by 30 s), so the books may be said not to close; that is not a divergence."""
    sim = Simulator(load_scene("release").replace(integrator="semi_implicit_euler",
                                                  tolerance=0.0, step_size=0.01))
    sim.run(10.0)
    assert sim.diverged is None and sim.steps == 1000
    assert sim.fault is None or "the energy books do not close" in sim.fault
    assert 19.0 < sim.energy_in_play < 30.0


def test_the_guard_scale_does_not_depend_on_where_the_potential_is_zero():
    """The same motion seen from two starting poses of equal energy above the lowest."""
    a = Simulator(load_scene("release"))
    b = Simulator(load_scene("release").replace(initial_positions=(3.14159265358979, 0.0)))
    assert abs(guard.scale(a, a.state) - guard.scale(b, b.state)) < 1e-9
    assert abs(a.energy_in_play - 2 * 9.81) < 1e-9


def test_books_that_do_not_close_end_the_run_in_failure(capsys):
    # explicit Euler on an undamped arm gains energy from nothing at 10 ms
    code = cli.main(["run", "--set", "integrator=euler", "--tolerance", "0",
                     "--duration", "10", "--json"])
    out, err = capsys.readouterr()
    assert code == 1
    assert err.count("energy books do not close") == 1 and "books at t" in err
    assert '"fault": "at t = ' in out


@pytest.mark.parametrize("argv", [
    ["run", "--tolerance", "1e-7", "--duration", "0.5"],
    ["run", "--tolerance", "0", "--max-substeps", "5", "--duration", "0.5"],
    ["accuracy", "--tolerance", "1e-6", "--duration", "0.2", "--integrators", "rk4",
     "--steps", "0.01", "--tolerances", "1e-8"],
])
def test_tolerance_is_an_option_of_the_commands(argv, capsys):
    assert cli.main(argv) == 0


def test_batch_says_it_cannot_honour_a_tolerance(capsys):
    assert cli.main(["batch", "--tolerance", "1e-6", "--count", "3"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "cannot honour a tolerance" in err
    assert cli.main(["batch", "--tolerance", "0", "--count", "3", "--duration", "0.05"]) == 0




def test_the_node_reports_books_that_do_not_close_as_an_error():
    from arm_sim_ros.interface import ERROR
    from arm_sim_ros.node.status import health
    sim = Simulator(load_scene("release").replace(integrator="euler", tolerance=0.0))
    sim.run(10.0)
    assert sim.books_fault and health(False, 0, 0, sim.books_fault) == (ERROR, sim.books_fault)
    assert health(False, 0, 0, None)[0] != ERROR


def test_a_contact_too_stiff_to_resolve_is_refused_at_once_not_run_for_ever():
    """Issue 24: an engaged compliant limit with damping 1e12 asked for ~1e12 sub-steps a
    step and never ended; past the planner's bound the step is refused, said in the
    physics' words."""
    scene = load_scene("compliant_limit").replace(**{"joint_limits.damping": 1e12},
                                                  initial_positions=(1.3, 0.0))
    sim = Simulator(scene)
    sim.run(0.05)
    assert sim.holding and "compliant limit is engaged" in sim.fault
    assert sim.state[:2] == (1.3, 0.0)


def counted_rhs(sim):
    """The simulator's rhs, counting its evaluations in `calls[0]`."""
    calls, rhs = [0], sim._rhs

    def f(*state):
        calls[0] += 1
        return rhs(*state)
    return f, calls


@pytest.mark.parametrize("n", [2, 3, 4, 7, 11])
def test_a_split_step_is_checked_against_half_as_many_again_finer_sub_steps(n):
    """A step of 1 < n < THREE_LEVELS sub-steps is taken again as m = ceil(3n/2) sub-steps,
    whose error is (n/m)^4 times its own for rk4: its signed error is (step - fine) /
    (1 - (n/m)^4), at the price of m sub-steps (2n halves; ceil(n/2) coarser ones before,
    whose estimate carried the next error term twice over: issue 47's spins)."""
    sim = Simulator(load_scene("release"))
    books, y, h = sim.accuracy, sim.state, sim.step_size
    f, calls = counted_rhs(sim)
    step, error, scaled, signed = books.measure(f, y, h, n)
    m = -(-3 * n // 2)
    fine = substepping(sim._step, m)(sim._rhs, y, h)
    assert step == substepping(sim._step, n)(sim._rhs, y, h)
    assert signed == [(a - c) / (1.0 - (n / m) ** 4) for a, c in zip(step[:4], fine)]
    assert error == max(abs(e) for e in signed)
    assert calls[0] == 4 * (n + m)


@pytest.mark.parametrize("n", [THREE_LEVELS, 13, 33])
def test_a_step_of_many_sub_steps_is_checked_against_two_coarser_counts(n):
    """From THREE_LEVELS on, against ceil(n/2) and ceil(n/3) sub-steps: their differences from
    the step give both the leading error term and the next (C N^-4 + D N^-5), so the
    estimate is the step's error to that order, at the price of 5n/6 sub-steps; exact for
    errors of that form (checked on the weights)."""
    sim = Simulator(load_scene("release"))
    books, y, h = sim.accuracy, sim.state, sim.step_size
    f, calls = counted_rhs(sim)
    step, error, scaled, signed = books.measure(f, y, h, n)
    m1, m2 = -(-n // 2), -(-n // 3)
    one, two = (substepping(sim._step, m)(sim._rhs, y, h) for m in (m1, m2))
    r1, r2 = n / m1, n / m2
    det = (r1 ** 4 - 1.0) * (r2 ** 5 - 1.0) - (r1 ** 5 - 1.0) * (r2 ** 4 - 1.0)
    w1, w2 = r2 ** 4 * (r2 - 1.0) / det, -(r1 ** 4) * (r1 - 1.0) / det
    assert signed == [w1 * (a - b) + w2 * (c - b) for a, c, b in zip(one, two, step[:4])]
    assert calls[0] == 4 * (n + m1 + m2)
    for c, d in ((1.0, 0.0), (0.0, 1.0), (0.3, -2.0)):      # e(N) = c N^-4 + d N^-5
        e = lambda count: c * count ** -4 + d * count ** -5
        assert w1 * (e(m1) - e(n)) + w2 * (e(m2) - e(n)) == pytest.approx(e(n), rel=1e-12)


def test_a_check_at_one_sub_step_or_where_the_plan_needs_them_takes_none_fewer():
    """A single sub-step is checked against its 2 halves; a plan's stability sub-steps are
    never checked against fewer than the plan asks (they would not be stable): against
    finer ones."""
    sim = Simulator(load_scene("release"))
    f, calls = counted_rhs(sim)
    sim.accuracy.measure(f, sim.state, sim.step_size, 1)
    assert calls[0] == 4 * 3
    stiff = Simulator(load_scene("damped_release").replace(damping=600.0))
    books = stiff.accuracy
    n = max(THREE_LEVELS, books.base + 1)
    assert -(-n // 3) < books.base
    f, calls = counted_rhs(stiff)
    books.measure(f, stiff.state, stiff.step_size, n)
    assert calls[0] == 4 * (n + -(-3 * n // 2))
