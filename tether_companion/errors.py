"""Typed errors that the command line turns into a clear message and exit code 2."""

from __future__ import annotations


class InputError(ValueError):
    """An input file (flight log, recording, scenario) is missing, truncated or lacks data.

    The message names the file and what is wrong or missing.
    """
