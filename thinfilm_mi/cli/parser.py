"""What every command shares: one argument parser class, and one place that turns
an error into a line on stderr and an exit status.

Exit statuses (every command): 0 success; 2 bad input
(:class:`~thinfilm_mi.errors.UsageError`, including a missing optional
dependency, :class:`~thinfilm_mi.errors.MissingExtra`; and
:class:`~thinfilm_mi.errors.ThinFilmError` or any ``ValueError`` a tool command
reports); 130 interrupted (Ctrl-C); 1 anything else
(:class:`~thinfilm_mi.errors.RenderFailure`, a failure while writing). A reader that
closes the output early (``python -m thinfilm_mi materials | head``) ends the command
quietly, with the status of a process a closed pipe stops (141).
"""
from __future__ import annotations

import argparse
import os
import sys
import traceback

from thinfilm_mi.batch.scene import one_line
from thinfilm_mi.errors import RenderFailure, UsageError

__all__ = ["ArgumentParser", "exit_code", "report_error", "failure", "run_command",
           "CLOSED_PIPE"]

#: The exit status after the reader closed stdout: a shell's for a process SIGPIPE stops.
CLOSED_PIPE = 141


class ArgumentParser(argparse.ArgumentParser):
    """argparse that raises :class:`~thinfilm_mi.errors.UsageError` instead of
    printing the usage and exiting, so every error is reported the same way
    (:func:`report_error`: one line). ``--help`` still exits (``SystemExit``)."""

    def error(self, message: str):  # noqa: D401 - argparse API
        raise UsageError(message)


def exit_code(error: BaseException) -> int:
    """The exit status of a command that stopped on ``error`` (see the module docstring)."""
    if isinstance(error, KeyboardInterrupt):
        return 130
    if isinstance(error, (UsageError, ValueError)):
        return 2
    return 1


def report_error(prog: str, error: BaseException, verbose: bool = False) -> int:
    """Print ``PROG: error: MESSAGE`` (one line, :func:`~thinfilm_mi.batch.scene.one_line`)
    on stderr, after the traceback of the error's cause with ``verbose``; return
    :func:`exit_code`."""
    if verbose:
        cause = error.__cause__ or error
        traceback.print_exception(type(cause), cause, cause.__traceback__, file=sys.stderr)
    print(f"{prog}: error: {one_line(str(error))}", file=sys.stderr)
    sys.stderr.flush()
    return exit_code(error)


def failure(cause: BaseException, message: str | None = None) -> RenderFailure:
    """A :class:`~thinfilm_mi.errors.RenderFailure` (exit 1) for an error the library
    did not foresee, chained to it (``--verbose`` prints its traceback); ``message``
    defaults to the error's type and text."""
    error = RenderFailure(message if message is not None else f"{type(cause).__name__}: {one_line(cause)}")
    error.__cause__ = cause
    return error


def run_command(command, args) -> int:
    """``command(args)``, ended quietly where the reader closes stdout early: Python would
    otherwise print a traceback for the ``BrokenPipeError``, and again at exit when it
    flushes stdout (hence stdout pointed at ``os.devnull``)."""
    try:
        rc = command(args)
        sys.stdout.flush()
        return rc
    except BrokenPipeError:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return CLOSED_PIPE
