"""Exit codes of the ``rehabbot`` command and the mapping from the libraries' exceptions.

====  ============================================================================
code  meaning
====  ============================================================================
0     success
1     runtime failure: a missing or damaged file, an unwritable output, no display,
      a missing optional dependency, a run that cannot go on
2     bad usage: unknown id, algorithm, scene or camera, an invalid value
130   training interrupted by SIGINT (Ctrl-C), resumable; 143 for SIGTERM
====  ============================================================================
"""

from __future__ import annotations

import argparse
import functools
from collections.abc import Callable

EXIT_OK = 0
EXIT_FAILURE = 1
EXIT_USAGE = 2


class CliError(Exception):
    """An error reported to the user as one line, with an exit code."""

    def __init__(self, message: str, exit_code: int = EXIT_FAILURE) -> None:
        super().__init__(message)
        self.exit_code = exit_code


def exit_code_for(err: BaseException) -> int:
    """The exit code for an exception a library raised (see the module docstring)."""
    from rehabbot.common.errors import RehabbotError, UsageError

    code = getattr(err, "exit_code", None)  # TrainingInterrupted: 128 + the signal number
    if isinstance(code, int) and not isinstance(err, RehabbotError):
        return code
    if isinstance(err, UsageError):
        return EXIT_USAGE
    if isinstance(err, (RehabbotError, OSError, RuntimeError, ImportError)):
        return EXIT_FAILURE
    if isinstance(err, (ValueError, TypeError)):
        return EXIT_USAGE
    return EXIT_FAILURE


def as_cli_error(err: BaseException) -> CliError:
    """``err`` as a one-line :class:`CliError` with its exit code."""
    if isinstance(err, CliError):
        return err
    message = str(err)
    if isinstance(err, OSError) and not message:
        message = f"{err.strerror or type(err).__name__}: {err.filename}"
    return CliError(message, exit_code_for(err))


LIBRARY_ERRORS: tuple[type[BaseException], ...] = (ValueError, OSError, RuntimeError,
                                                     ImportError)


def cli_command(func: Callable[[argparse.Namespace], int]) -> Callable[[argparse.Namespace], int]:
    """Run a command function, turning the libraries' errors into one-line
    :class:`CliError` with the exit code of :func:`exit_code_for`."""

    @functools.wraps(func)
    def run(args: argparse.Namespace) -> int:
        from rehabbot.common.errors import RehabbotError

        try:
            return func(args)
        except CliError:
            raise
        except (RehabbotError, *LIBRARY_ERRORS) as err:
            raise as_cli_error(err) from err

    return run
