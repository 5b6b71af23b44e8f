"""The command line's parser and how a command ends: exit codes, one-line errors and warnings.

:class:`Parser` gives argparse's errors on one line (exit 2) and takes negative numbers as option
values; :func:`run_command` runs a sub-command and maps what it raises to the exit codes of
:mod:`.common` (0 success, 2 bad input, 1 unexpected failure, 130 interrupted).
"""

from __future__ import annotations

import argparse
import errno
import re
import sys
import warnings
from collections.abc import Callable
from typing import NoReturn

from fault_tolerance.cli.common import EXIT_BAD_INPUT, EXIT_FAILURE, EXIT_INTERRUPTED, close_bars
from fault_tolerance.errors import FaultToleranceError

#: Option values that begin with ``-`` and are numbers, not options: ``-0.21``, ``-1e-3``,
#: ``-0.21,0.20,0.35``, ``-1.5:1.5,-2:2``. argparse's own pattern takes only a single plain number,
#: so ``--x0 -0.21,0.20,0.35`` failed ("expected one argument").
NEGATIVE_NUMBERS = re.compile(r"^-(\d|\.\d)[\d.eE+\-,:;]*$")


#: Attribute of the parsed namespace that records the options given so far (by destination).
GIVEN = "_options_given"
#: Attribute of the parsed arguments: the destinations of the options given on the command line
#: (``--gain`` → ``"gain"``), so a command can tell a value given from a default.
GIVEN_OPTIONS = "given_options"


def repeatable(parser: argparse.ArgumentParser) -> list[str]:
    """The options of ``parser`` that may repeat (``action="append"``), e.g. ``--option``."""
    return [a.option_strings[0] for a in parser._actions if isinstance(a, argparse._AppendAction)]


def _may_repeat(parser: argparse.ArgumentParser) -> str:
    """``only --package-dir, --xacro-arg and --option may repeat`` (or that none may)."""
    opts = repeatable(parser)
    if not opts:
        return "no option of this command may repeat"
    listed = opts[0] if len(opts) == 1 else f"{', '.join(opts[:-1])} and {opts[-1]}"
    return f"only {listed} may repeat"


def _refuse_repeat(parser: argparse.ArgumentParser, action: argparse.Action, namespace, used):
    """``parser.error`` when ``action``'s option was already given on this command line."""
    if not action.option_strings:
        return
    given = namespace.__dict__.setdefault(GIVEN, {})
    if action.dest in given:
        first = "" if given[action.dest] == used else f" (first as {given[action.dest]})"
        parser.error(f"{used} given twice{first}; give it once ({_may_repeat(parser)})")
    given[action.dest] = used


class StoreOnce(argparse._StoreAction):
    """``store`` that refuses a second value: ``--lockable a --lockable b`` is an error, not b."""

    def __call__(self, parser, namespace, values, option_string=None):
        """Store ``values`` unless the option was given before."""
        _refuse_repeat(parser, self, namespace, option_string)
        super().__call__(parser, namespace, values, option_string)


class StoreTrueOnce(argparse._StoreTrueAction):
    """``store_true`` that refuses the flag given twice (``--html --html``)."""

    def __call__(self, parser, namespace, values, option_string=None):
        """Set the flag unless it was given before."""
        _refuse_repeat(parser, self, namespace, option_string)
        super().__call__(parser, namespace, values, option_string)


class Parser(argparse.ArgumentParser):
    """argparse with a one-line error message (exit code 2); values may be negative numbers.

    Every subcommand's parser is of this class (``add_subparsers`` uses the parent's class), so
    any option taking numbers accepts ``--opt -1,2`` as well as ``--opt=-1,2``. An option given
    twice is an error (exit 2, "given twice"), except those declared ``action="append"``
    (``--package-dir``, ``--xacro-arg``, ``--option``), whose values merge.
    """

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = NEGATIVE_NUMBERS
        self.register("action", None, StoreOnce)
        self.register("action", "store", StoreOnce)
        self.register("action", "store_true", StoreTrueOnce)

    def parse_known_args(self, args=None, namespace=None):
        """Argparse's parse; the options given are in ``given_options`` (their destinations)."""
        ns, extra = super().parse_known_args(args, namespace)
        given = ns.__dict__.pop(GIVEN, {})
        setattr(ns, GIVEN_OPTIONS, frozenset(given) | getattr(ns, GIVEN_OPTIONS, frozenset()))
        return ns, extra

    def error(self, message: str) -> NoReturn:
        """Exit 2 with one line on stderr."""
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def run_command(func: Callable, args: argparse.Namespace) -> int:
    """Run one command; map errors to exit codes and warnings to one line on stderr."""
    shown = warnings.showwarning
    if not args.debug:  # a warning is one line on stderr too
        warnings.showwarning = _warning_line
    try:
        return int(func(args) or 0)
    except FaultToleranceError as err:
        close_bars()
        if args.debug:
            raise
        print(f"fault-tolerance {args.command}: error: {one_line(err)}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        close_bars()
        print("interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:  # `fault-tolerance robots | head`: the reader left, not an error
        _quiet_stdout()
        return 0
    except Exception as err:  # noqa: BLE001 - the last line of defence
        close_bars()
        if args.debug:
            raise
        if isinstance(err, OSError) and err.errno in _REFUSED_BY_THE_SYSTEM:
            # the file system refused (full, read-only, permissions, a name too long): not a bug
            print(f"fault-tolerance {args.command}: error: {one_line(err)}", file=sys.stderr)
            return EXIT_BAD_INPUT
        print(
            f"fault-tolerance {args.command}: unexpected error: {type(err).__name__}: "
            f"{one_line(err)} (run with --debug for the traceback)",
            file=sys.stderr,
        )
        return EXIT_FAILURE
    finally:
        warnings.showwarning = shown


def _quiet_stdout() -> None:
    """Point stdout at /dev/null so the interpreter's final flush does not fail again."""
    import os

    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):  # pragma: no cover - stdout without a file descriptor
        pass
    finally:
        os.close(devnull)


#: errno values of an OSError that mean the system refused the output, not that the code is wrong.
_REFUSED_BY_THE_SYSTEM = frozenset(
    {errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EACCES, errno.EPERM, errno.ENAMETOOLONG}
)


def one_line(message) -> str:
    """``message`` on one line."""
    return " ".join(str(message).split("\n"))


def _warning_line(message, category, filename, lineno, file=None, line=None) -> None:
    print(f"fault-tolerance: warning: {one_line(message)}", file=sys.stderr)
