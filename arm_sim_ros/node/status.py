"""How the node says it is doing: the level and message of its 1 Hz DiagnosticStatus, and
the one-line status it prints each second."""
from __future__ import annotations

from ..interface import ERROR, OK, WARN


def health(held: bool, new_refused: int, new_late: int) -> tuple[int, str]:
    """(diagnostic level, message) over the interval since the previous status."""
    if held:
        return ERROR, "integration not finite: holding the last finite state"
    if new_refused or new_late:
        return WARN, f"{new_refused} refused commands, {new_late} late ticks in the last interval"
    return OK, "running"


def status_line(sim, held: bool, rtf: float, refused_commands: int) -> str:
    residual = "held" if held else f"{sim.residual():+.2e} J"
    return (f"t = {sim.time:9.3f} s   real-time factor {rtf:6.2f}   energy residual "
            f"{residual}   refused commands {refused_commands}")
