"""Bad input from a person: one line on stderr and exit code 2, never a traceback.

Every layer may raise `UsageError`; the front ends (`arm-sim`, `arm_sim_node`) print it.
"""
from __future__ import annotations

import argparse


class UsageError(ValueError):
    """Bad input on the command line or in a file; printed as one line, exit code 2."""


class ArgumentParser(argparse.ArgumentParser):
    """argparse that raises UsageError instead of printing usage and exiting."""

    def error(self, message):
        raise UsageError(message)
