"""The `sparse-body` command: a dispatcher. Each command is a module of apps/commands/ with
add_parser(sub) (its arguments, and run as what it calls) and run(args) -> exit code; this
file builds the parser from them and turns every way a run can end into one line and an
exit code (apps/commands/exits.py).

Kept at the package's top level as the entry point that users and tests name
(`sparse-body`, `python -m sparse_body.cli`)."""

from __future__ import annotations

import argparse
import importlib
import sys

from .apps.commands import exits
from .apps.commands.common import USER_DESCRIPTION, DefaultOnceFormatter, OneLineParser, choices_text
from .apps.commands.exits import (  # noqa: F401 - the exit codes, named where users and tests look
    EXIT_INPUT,
    EXIT_INTERRUPTED,
    EXIT_OS,
    EXIT_OUTPUT,
    EXIT_TERMINATED,
    EXIT_TOO_LARGE,
    EXIT_USAGE,
    Terminated,
)

# The commands, in the order --help lists them: each a module apps/commands/<name>.py.
COMMANDS = ("demo", "eval", "make_bag", "process", "view", "bench", "train", "import_mocap", "options", "split")


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(prog="sparse-body", description=USER_DESCRIPTION, epilog=choices_text())
    sub = parser.add_subparsers(dest="command", required=True)
    add = sub.add_parser
    # every subcommand's --help shows the defaults and what can be chosen
    sub.add_parser = lambda *a, **k: add(  # type: ignore[method-assign]
        *a, formatter_class=DefaultOnceFormatter, epilog=choices_text(), **k
    )
    for name in COMMANDS:
        importlib.import_module(f"{__package__}.apps.commands.{name}").add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> None:
    """Run a subcommand; every error a user can cause ends in one line on stderr and its own
    exit code, never a traceback."""
    import signal

    exits.SEEN.clear()
    command = "sparse-body"
    yaml_error: type[Exception] = ValueError  # (yaml's own until it is imported)
    args = None
    try:  # from the first statement: Ctrl-C while starting is one line too
        signal.signal(signal.SIGTERM, exits.on_sigterm)
        if signal.getsignal(signal.SIGINT) is signal.default_int_handler:  # (not where it is ignored)
            signal.signal(signal.SIGINT, exits.on_sigint)
        from yaml import YAMLError

        yaml_error = YAMLError

        args = build_parser().parse_args(argv)
        command = f"sparse-body {args.command}"
        if exits.SEEN:  # a stop that an import swallowed: nothing has started
            raise Terminated if "SIGTERM" in exits.SEEN else KeyboardInterrupt
        sys.exit(args.func(args))
    except (KeyboardInterrupt, Exception) as err:  # (SystemExit passes: argparse's, ours)
        stop = exits.stop_behind(err)
        # what a stop leaves: a command that keeps finished parts says so on its own args
        left = getattr(args, "left_when_stopped", "nothing written")
        if isinstance(stop, Terminated) or (stop is not None and "SIGTERM" in exits.SEEN):
            print(f"{command}: terminated; {left}", file=sys.stderr)
            sys.exit(EXIT_TERMINATED)
        if stop is not None:  # partial output was removed on the way out
            print(f"{command}: interrupted; {left}", file=sys.stderr)
            sys.exit(EXIT_INTERRUPTED)
        if isinstance(err, ModuleNotFoundError) and err.name in exits.TRAINING_MODULES:
            print(f"{command}: {exits.needs_training_tools(err.name)}", file=sys.stderr)
            sys.exit(EXIT_INPUT)
        # ValueError includes MotionFileError, BagError, OutputError, SensorConfigError, CalibrationError
        if not isinstance(err, (ValueError, OSError, EOFError, yaml_error, MemoryError, RecursionError)):
            raise  # a bug, not something the user caused: its traceback is what we need
        print(f"{command}: {exits.one_line(err)}", file=sys.stderr)
        sys.exit(exits.exit_code(err))


if __name__ == "__main__":
    main()
