"""When the next tick is due: publish_rate x real_time_factor ticks per wall second, or, in
lockstep, when the command that answers the latest state has come (Lockstep).

Both transports pace their ticks with it. A late tick is counted by the core; the ticks
then follow back to back until the schedule is met again, unless it is more than CATCH_UP
behind, when the schedule restarts from now instead of bursting (a stalled machine must not
be followed by seconds of flat-out ticking)."""
from __future__ import annotations

CATCH_UP = 0.05   # wall seconds of lag made up by ticking back to back (scheduler jitter)


class TickSchedule:
    def __init__(self, now: float):
        self.next_tick = now

    def wait(self, now: float) -> float:
        """Wall seconds until the next tick is due (≤ 0: due now)."""
        return self.next_tick - now

    def run_due(self, core, tick) -> int:
        """A tick timer's callback (the rclpy transport's): `tick()` for every tick due, on
        the core's wall clock and current wall period, so a late callback still keeps
        real_time_factor; at most CATCH_UP s of ticks, so commands and services are served
        between. In lockstep the commands tick: it returns at once. Returns the ticks run."""
        if core.config.values["lockstep"]:
            return 0
        now = started = core.wall_clock()
        ran = 0
        while self.wait(now) <= 0 and now - started <= CATCH_UP:
            tick()
            self.ticked(now, core.config.wall_period)
            ran += 1
            now = core.wall_clock()
        return ran

    def ticked(self, now: float, period: float) -> None:
        """A tick ran at `now`; the next is one `period` (the current wall period) later."""
        self.next_tick += period
        if self.next_tick < now - max(period, CATCH_UP):
            self.next_tick = now


class Lockstep:
    """Which command answers which state, in lockstep: a closed loop ordered by its messages,
    not by the wall clock.

    Every state the node publishes in lockstep awaits the command that answers it, and a tick
    happens when, and only when, that command has arrived (and the simulation may move: a
    paused node holds the answer until it plays or is stepped). A command names the state it
    answers by carrying its stamp (a JointState command's header.stamp, copied from the
    joint_states message it answers); it then answers the latest state, or an earlier one
    (stale: a second answer to a state already answered, neither taken nor ticked). A command
    with no stamp (Float64MultiArray; a JointState stamped 0, or by a clock the node's stamps
    never showed, as ros2_control's hardware interface stamps its own) answers the latest
    state on arrival."""

    RESEND = 1.0                    # wall s: an unanswered state goes out again (delivery)

    def __init__(self):
        self.published = None       # the stamp of the latest state published in lockstep
        self.sent = (0, -float("inf"))   # (matched readers, wall time) when it last went out
        self.answered = False       # its answer has come, the tick has not yet happened
        self.stale = 0              # answers to states answered already
        self.states = []            # states of lockstep ticks the transport has not published

    def answers(self, stamp_ns: int | None, origin_ns: int) -> bool:
        """Whether a command stamped `stamp_ns` answers the latest state (else: stale)."""
        latest = self.published
        return not stamp_ns or latest is None or stamp_ns >= latest or stamp_ns < origin_ns

    def latest(self, data):
        """`data` (a JointStateData) is the latest state, published once: it awaits its
        answer."""
        self.published, self.answered = data.stamp_ns, False
        self.sent = (self.sent[0], float("inf"))      # just went out: RESEND from the next look
        return data

    def resend(self, readers: int, now: float) -> bool:
        """Whether the latest state, unanswered, goes out again now: to a reader that has
        matched since (the first moment it can reach it), or RESEND after it last went out
        (a reader that had matched by count before it could take it). It only repeats a
        state: an answer to the copy after the first is stale, so nothing is reordered."""
        count, when = self.sent
        when = now if when == float("inf") else when     # published since: from this look
        due = self.published is not None and not self.answered and (
            readers > count or now - when >= self.RESEND)
        self.sent = (readers, now if due else when)
        return due

    def queue(self, data) -> None:
        """The latest state, for the transport to publish (take)."""
        self.states.append(self.latest(data))

    def take(self) -> list:
        """The states not yet published, in order."""
        states, self.states = self.states, []
        return states


