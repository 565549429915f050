"""Bad input from a person: one line on stderr and exit code 2, never a traceback.

Every layer may raise `UsageError`; the front ends (`arm-sim`, `arm_sim_node`) print it.
"""
from __future__ import annotations

import argparse
import difflib
import unicodedata

# Exit codes of `arm-sim` and `arm_sim_node`, in one place (docs/reference/exit_codes.md).
DONE, FAULT, REFUSED, STOPPED, BROKEN_PIPE = 0, 1, 2, 130, 141
EXIT_CODES = {
    DONE: "done (the node: also stopped by SIGINT or SIGTERM)",
    FAULT: "the work failed: `arm-sim run` faulted (a step was refused: `fault` and "
           "`refused_steps` in `--json`), `arm-sim fit` did not converge, `arm-sim send-torque` "
           "found no subscriber, `arm-sim record` received no message (no bag is left)",
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
