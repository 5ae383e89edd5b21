"""Exit codes of the ``rehabbot`` command and the mapping from the libraries' exceptions.

====  ============================================================================
code  meaning
====  ============================================================================
0     success
1     runtime failure: a missing or damaged file, an unwritable output, no display,
      a missing optional dependency, a run that cannot go on
2     bad usage: unknown id, algorithm, scene or camera, an invalid value
130   interrupted by SIGINT (Ctrl-C): any command; training is resumable (143 for
      SIGTERM during training)
141   standard output was closed early (``rehabbot list | head``), as a shell reports
      SIGPIPE; nothing is printed
====  ============================================================================

Every failure reaches the user as one line on stderr, ``rehabbot: error: ...``, never a
traceback (:func:`report`): the libraries' own exceptions with their message, a damaged
file read by a third-party loader (pickle, zip) as a failure naming the error, anything
unforeseen as its type and message. Python's warnings from third-party packages are not
shown (:func:`quiet_third_parties`).
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import json
import math
import pickle
import sys
import warnings
import zipfile
from collections.abc import Callable, Iterator

EXIT_OK = 0
EXIT_FAILURE = 1
EXIT_USAGE = 2
EXIT_SIGINT = 130  # 128 + SIGINT, as a shell reports a command stopped by Ctrl-C

# What third-party loaders (pickle, zipfile, numpy) raise on a truncated or damaged file.
DAMAGED_FILE_ERRORS: tuple[type[BaseException], ...] = (pickle.UnpicklingError, EOFError,
                                                        zipfile.BadZipFile)


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
    if isinstance(err, (RehabbotError, OSError, RuntimeError, ImportError, *DAMAGED_FILE_ERRORS)):
        return EXIT_FAILURE
    if isinstance(err, (ValueError, TypeError)):
        return EXIT_USAGE
    return EXIT_FAILURE


def _message(err: BaseException) -> str:
    message = str(err)
    if isinstance(err, ModuleNotFoundError) and "pip install" not in message:
        from rehabbot.common.extras import OPTIONAL_MODULES, install_hint

        name = (err.name or "").split(".", 1)[0]
        if name in OPTIONAL_MODULES:  # an optional dependency imported without a hint
            return f"{message}: {install_hint(name)}"
    if isinstance(err, OSError) and not message:
        return f"{err.strerror or type(err).__name__}: {err.filename}"
    if isinstance(err, DAMAGED_FILE_ERRORS):
        return f"a damaged or truncated file ({type(err).__name__}: {message or 'no data'})"
    from rehabbot.common.errors import RehabbotError

    if not isinstance(err, (RehabbotError, ValueError, OSError, RuntimeError, ImportError)):
        return f"{type(err).__name__}: {message}"  # unforeseen: say what it was
    return message or type(err).__name__


def as_cli_error(err: BaseException) -> CliError:
    """``err`` as a one-line :class:`CliError` with its exit code."""
    if isinstance(err, CliError):
        return err
    return CliError(_message(err), exit_code_for(err))


def one_line(text: str) -> str:
    """``text`` with every run of whitespace (newlines included) as one space."""
    return " ".join(str(text).split())


def report(err: BaseException) -> int:
    """Print ``err`` as one line on stderr (``rehabbot: error: ...``; an interrupt as
    ``rehabbot: interrupted``) and return its exit code; never a traceback."""
    if isinstance(err, KeyboardInterrupt):
        print("rehabbot: interrupted (Ctrl-C); finished output files are kept, "
              "unfinished ones were not written", file=sys.stderr, flush=True)
        return EXIT_SIGINT
    cli_error = as_cli_error(err)
    print(f"rehabbot: error: {one_line(str(cli_error))}", file=sys.stderr, flush=True)
    return cli_error.exit_code


def _drop_unraisable(_unraisable: object) -> None:
    """An error in a third party's ``__del__`` (imageio after a failed write) is not the
    user's business: the command has already reported the failure that caused it."""


@contextlib.contextmanager
def quiet_third_parties() -> Iterator[None]:
    """While a command runs: Python warnings from modules outside ``rehabbot`` are not
    shown, and errors raised in ``__del__`` methods are not printed."""
    previous_hook = sys.unraisablehook
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore")
        warnings.filterwarnings("default", module=r"rehabbot(\.|$)")
        sys.unraisablehook = _drop_unraisable
        try:
            yield
        finally:
            sys.unraisablehook = previous_hook


def non_negative_int(text: str) -> int:
    """An argparse type: an integer >= 0 (a reset seed), naming the bad value."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be an integer >= 0, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be an integer >= 0, got {value}")
    return value


def bounded_int(low: int, high: int) -> Callable[[str], int]:
    """An argparse type: an integer in ``[low, high]``, naming the bad value. Every count a
    command takes has an upper bound too (episodes, steps, frames), so that a typo such as
    ``1e26`` is refused at once instead of running for ever or overflowing later."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            try:
                number = float(text)
            except ValueError:
                number = math.nan
            if not number.is_integer():
                raise argparse.ArgumentTypeError(
                    f"must be an integer in [{low}, {high:,}], got {text!r}") from None
            value = int(number)
        if not low <= value <= high:
            raise argparse.ArgumentTypeError(f"must be an integer in [{low}, {high:,}], "
                                             f"got {text!r}")
        return value

    parse.__name__ = "int"  # argparse names the type in its message: "invalid int value"
    return parse


def bounded_float(low: float, high: float, *, low_open: bool = False) -> Callable[[str], float]:
    """An argparse type: a finite number in ``[low, high]`` (``(low, high]`` with
    ``low_open``), naming the bad value; ``nan`` and ``inf`` are refused."""
    interval = f"{'(' if low_open else '['}{low:g}, {high:g}]"

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        below = value <= low if low_open else value < low
        if not math.isfinite(value) or below or value > high:
            raise argparse.ArgumentTypeError(f"must be a number in {interval}, got {text!r}")
        return value

    parse.__name__ = "float"
    return parse


LIBRARY_ERRORS: tuple[type[BaseException], ...] = (ValueError, OSError, RuntimeError,
                                                     ImportError, *DAMAGED_FILE_ERRORS)


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


def json_object(text: str) -> dict:
    """An argparse type: a JSON object."""
    try:
        value = json.loads(text)
    except json.JSONDecodeError as err:
        raise argparse.ArgumentTypeError(f"not valid JSON: {err}") from None
    if not isinstance(value, dict):
        raise argparse.ArgumentTypeError(f"must be a JSON object, got {text!r}")
    return value


def env_kwargs_object(text: str) -> dict:
    """An argparse type: a JSON object of env keyword arguments. ``render_mode`` must be a
    string or null (Gymnasium fails on anything else with a traceback)."""
    value = json_object(text)
    mode = value.get("render_mode")
    if mode is not None and not isinstance(mode, str):
        raise argparse.ArgumentTypeError(f"render_mode must be a string or null, got {mode!r}")
    return value
