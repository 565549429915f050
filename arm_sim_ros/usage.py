"""Bad input from a person: one line on stderr and exit code 2, never a traceback.

Every layer may raise `UsageError`; the front ends (`arm-sim`, `arm_sim_node`) print it.
"""
from __future__ import annotations

import argparse
import unicodedata


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
