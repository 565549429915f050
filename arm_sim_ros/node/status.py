"""How the node says it is doing: the level and message of its 1 Hz DiagnosticStatus, and
the one-line status it prints each second."""
from __future__ import annotations

from ..interface import ERROR, OK, WARN


class Interval:
    """What changed since the previous 1 Hz status: simulated and wall time, refused commands,
    late ticks."""

    def __init__(self, wall: float, sim_time: float, refused: int, late: int):
        self.wall, self.sim_time, self.refused, self.late = wall, sim_time, refused, late

    def real_time_factor(self, wall_now: float, sim_time: float) -> float:
        wall = wall_now - self.wall
        return (sim_time - self.sim_time) / wall if wall > 0 else 0.0

    def close(self, wall_now: float, sim_time: float, refused: int, late: int) -> tuple:
        """(real-time factor, new refused commands, new late ticks) over the interval, which
        ends now; the next one starts."""
        closed = (self.real_time_factor(wall_now, sim_time), refused - self.refused,
                  late - self.late)
        self.__init__(wall_now, sim_time, refused, late)
        return closed


def health(held: bool, new_refused: int, new_late: int, books=None) -> tuple[int, str]:
    """(diagnostic level, message) over the interval since the previous status; `books`:
    why the energy books do not close (physics/trust/guard.py), an error until reset."""
    if held:
        return ERROR, "integration not finite: holding the last finite state"
    if books:
        return ERROR, books
    if new_refused or new_late:
        return WARN, f"{new_refused} refused commands, {new_late} late ticks in the last interval"
    return OK, "running"


def status_line(sim, held: bool, rtf: float, refused_commands: int) -> str:
    residual = "held" if held else f"{sim.residual():+.2e} J"
    return (f"t = {sim.time:9.3f} s   real-time factor {rtf:6.2f}   energy residual "
            f"{residual}   refused commands {refused_commands}")
