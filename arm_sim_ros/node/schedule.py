"""When the next tick is due: publish_rate x real_time_factor ticks per wall second.

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

    def ticked(self, now: float, period: float) -> None:
        """A tick ran at `now`; the next is one `period` (the current wall period) later."""
        self.next_tick += period
        if self.next_tick < now - max(period, CATCH_UP):
            self.next_tick = now
