"""How the node says it is doing: what its start line says is on, the level and message of its
1 Hz DiagnosticStatus, the one-line status it prints each second, and its stop line."""
from __future__ import annotations

from ..interface import ERROR, OK, WARN


class Console:
    """What the node core prints (a part of ArmSimCore): the pace counted from the first tick
    done, the status line each second and the stop line at the end."""

    began = None                    # (wall, stamp) when the run's first tick was done

    def first_tick_done(self) -> None:
        now = self.wall_clock()
        self.interval.begin(now, self.sim.time)
        self.began = self.began or (now, self.stamp_ns())

    def status_line(self, rtf: float) -> str:
        """The one-line status the node prints each second (no pace before the first tick)."""
        return status_line(self.sim, self.held, None if self.interval.waiting else rtf,
                           self.refused_commands)

    def stop_line(self, recorded: bool) -> str:
        """Where it stopped, at what pace since the first tick, what it wrote (`recorded`:
        the recording was finished whole), what it refused."""
        target = self.config.values["rerun_path"]
        elapsed = None if self.began is None else (
            (self.stamp_ns() - self.began[1]) / 1e9, self.wall_clock() - self.began[0])
        return stopped_line(self.sim.time, elapsed, recorded and target and f"wrote {target}",
                            self.refused_commands, self.late_ticks)


class Interval:
    """What changed since the previous 1 Hz status: simulated and wall time, refused commands,
    late ticks. A new simulator's first interval starts when its first tick is done
    (`begin`): the start-up before it (the transport, a first compile) is no pace, and the
    first status line read "real-time factor 0.00"."""

    def __init__(self, wall: float, sim_time: float, refused: int, late: int):
        self.wall, self.sim_time, self.refused, self.late = wall, sim_time, refused, late
        self.waiting = True                # for the first tick: no pace measured yet

    def begin(self, wall: float, sim_time: float) -> None:
        self.wall, self.sim_time, self.waiting = wall, sim_time, False

    def real_time_factor(self, wall_now: float, sim_time: float) -> float:
        wall = wall_now - self.wall
        return (sim_time - self.sim_time) / wall if wall > 0 else 0.0

    def close(self, wall_now: float, sim_time: float, refused: int, late: int) -> tuple:
        """(real-time factor, new refused commands, new late ticks) over the interval, which
        ends now; the next one starts."""
        closed = (self.real_time_factor(wall_now, sim_time), refused - self.refused,
                  late - self.late)
        waiting = self.waiting
        self.__init__(wall_now, sim_time, refused, late)
        self.waiting = waiting
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


def status_line(sim, held: bool, rtf: float | None, refused_commands: int) -> str:
    """`rtf` None: no tick done yet, so no pace to give."""
    residual = "held" if held else f"{sim.residual():+.2e} J"
    pace = "     -" if rtf is None else f"{rtf:6.2f}"
    return (f"t = {sim.time:9.3f} s   real-time factor {pace}   energy residual "
            f"{residual}   refused commands {refused_commands}")


def what_is_on(scene, values: dict, recording: bool) -> list:
    """The parts of the start line that say what is on beyond the plain arm: the error
    estimate, sensors (and where the truth goes), command latency, lockstep, the recording."""
    on = [f"estimate {scene.estimate}" + (f", tolerance {scene.tolerance:g}" if scene.estimate
                                          == "global" else ": no error estimate")]
    if scene.sensors is not None:
        modelled = [f"{key} {_value(value)}" for key, value in scene.sensors.items()
                    if key != "seed" and value not in (0.0, (0.0, 0.0), None, "true")]
        on.append(f"sensors ({', '.join(modelled) or 'modelling nothing'}): joint_states carries "
                  "the readings, ~/true_joint_states the truth")
    if scene.command_delay:
        on.append(f"command_delay {scene.command_delay:g} s")
    if values["lockstep"]:
        wait = values["lockstep_wait"]
        on.append("lockstep: one tick per command" + (
            f", or after {wait:g} s without one while a node listens on /clock" if wait else ""))
    targets = [f"recording {values['rerun_path']}" if values["rerun_path"] else "",
               "streaming to a new Rerun viewer" if values["rerun_spawn"] else "",
               f"streaming to the Rerun viewer at {values['rerun_connect']}"
               if values["rerun_connect"] else ""]
    if any(targets):
        on += [t for t in targets if t] if recording else ["Rerun telemetry off (see the error above)"]
    return on


def stopped_line(sim_time: float, elapsed: tuple | None, written: str, refused: int,
                 late: int) -> str:
    """The node's last line: where it stopped, its pace over the run (`elapsed`: simulated
    and wall seconds since its first tick, None before any), what it wrote, what it refused."""
    pace = ("before its first tick" if elapsed is None else
            f"{elapsed[0]:.3f} s simulated in {elapsed[1]:.2f} s since the first tick "
            f"(real-time factor {elapsed[0] / elapsed[1] if elapsed[1] > 0 else 0.0:.2f})")
    return (f"stopped at t = {sim_time:.3f} s, {pace}; {written or 'no recording'}; "
            f"{refused} commands refused, {late} late ticks")


def _value(value) -> str:
    if isinstance(value, tuple):
        return "[" + ", ".join(f"{v:g}" for v in value) + "]"
    return f"{value:g}" if isinstance(value, float) else str(value)
