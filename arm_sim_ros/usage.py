"""Bad input from a person: one line on stderr and exit code 2, never a traceback.

Every layer may raise `UsageError`; the front ends (`arm-sim`, `arm_sim_node`) print it.
"""
from __future__ import annotations

import argparse
import difflib
import sys
import unicodedata

# Exit codes of `arm-sim` and `arm_sim_node`, in one place (docs/reference/exit_codes.md).
DONE, FAULT, REFUSED, UNEXPLAINED, STOPPED, BROKEN_PIPE = 0, 1, 2, 3, 130, 141
EXIT_CODES = {
    DONE: "done (the node: also stopped by SIGINT or SIGTERM; `arm-sim fit`: the fitted "
          "model explains the recording)",
    FAULT: "the work failed: `arm-sim run` faulted (a step was refused: `fault` and "
           "`refused_steps` in `--json`), `arm-sim fit` stopped at a bound before it converged "
           "(which, and the best point) or the recording cannot identify a free key (which, "
           "and why: it moves nowhere beyond its noise, or the key acts nowhere in it), "
           "`arm-sim excite` faulted (no bag) or recorded a joint that never moved or whose "
           "readings show none of its motion, `arm-sim send-torque` found no subscriber or "
           "the node refused or ignores its commands (its /diagnostics say so), `arm-sim "
           "record` received no message (no bag is left)",
    UNEXPLAINED: "`arm-sim fit` converged, but the fitted model does not explain the "
                 "recording (its verdict: more than 2 x the noise); the outputs are written",
    REFUSED: "refused input: one line on stderr says what and how to fix it; nothing started "
             "or half-written",
    STOPPED: "`arm-sim` stopped by SIGINT, SIGTERM or SIGHUP; every output is closed at the "
             "same last step (`interrupted_at` in `--json`)",
    BROKEN_PIPE: "the reader of stdout went away (`| head`)",
}


class UsageError(ValueError):
    """Bad input on the command line or in a file; printed as one line, exit code 2."""


class ArgumentParser(argparse.ArgumentParser):
    """argparse that raises UsageError instead of printing usage and exiting."""

    def error(self, message):
        raise UsageError(message)


def exit_as_main(code: int):
    """sys.exit(code) for `python -m ...`: under -m, CPython (3.11 to 3.13, Modules/main.c)
    ends the process by SIGINT (-2) instead of `code` when a KeyboardInterrupt once passed
    through an exec of a string, however it was caught and handled after. numba and
    dataclasses exec strings, so a SIGTERM met inside a first tick's compile turned a clean
    stop (exit 0) into -2, one stop in six. A fresh exec clears that note (pythonrun.c
    run_eval_code_obj). The console scripts run as files and never met it."""
    exec("pass")
    sys.exit(code)


def one_line(message) -> str:
    """`message` as one printable line: control characters a user typed into a name or a
    value (a newline, a carriage return...) are shown escaped, never acted on."""
    return "".join(repr(c)[1:-1] if unicodedata.category(c).startswith("C") else c
                   for c in str(message))


def did_you_mean(word: str, choices) -> str:
    """`did you mean 'x'? ` for the choice closest to a misspelt `word` (a '-' for a '_'
    too), or "" when none is close."""
    close = difflib.get_close_matches(word.replace("-", "_"), list(choices), n=1, cutoff=0.6)
    return f"did you mean {close[0]!r}? " if close else ""
