"""How a command ends: one exit code per kind of error a user can cause, the error as one
line, and Ctrl-C / SIGTERM told apart from a failure (cli.main uses these)."""

from __future__ import annotations


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where the command is, so that partial output is removed on the way out
    as for Ctrl-C."""


# Exit codes: one per kind of error a user can cause (docs/outputs.md, the table).
EXIT_INPUT, EXIT_USAGE, EXIT_OUTPUT, EXIT_OS, EXIT_TOO_LARGE = 1, 2, 3, 4, 5
TRAINING_MODULES = ("torch", "roma", "onnx")  # requirements-train.txt: what `make setup` leaves out


def needs_training_tools(module: str) -> str:
    return (
        f"this needs the training tools ({module}), which the runtime install leaves out: "
        "make setup-train (or pip install -r requirements-train.txt)"
    )


EXIT_INTERRUPTED, EXIT_TERMINATED = 130, 143


def exit_code(err: BaseException) -> int:
    """The exit code of an error the command ends with (see the constants above)."""
    from ...core.file_output import OutputError
    from ...core.textfile import InputTooLarge

    if isinstance(err, OutputError):
        return EXIT_OUTPUT
    if isinstance(err, (InputTooLarge, MemoryError, RecursionError)):
        return EXIT_TOO_LARGE
    if isinstance(err, OSError):
        return EXIT_OS
    return EXIT_INPUT


MAX_MESSAGE = 2000  # characters of an error's one line


def one_line(err: BaseException) -> str:
    if isinstance(err, MemoryError):
        return "out of memory (a smaller input, or a shorter --seconds / --limit)"
    if isinstance(err, RecursionError):
        return "input nested too deeply"
    if isinstance(err, OSError) and err.strerror:
        where = f"{err.filename}: " if err.filename else ""
        return f"{where}{err.strerror}"
    text = " ".join(str(err).split()) or type(err).__name__
    # an error quoting what it refused stays readable whatever that was (a value of megabytes)
    return text if len(text) <= MAX_MESSAGE else text[: MAX_MESSAGE - 20] + " ... (cut short)"


SEEN: set[str] = set()  # the stop signals seen ("SIGINT", "SIGTERM"); cli.main clears it at its start


def on_sigint(signum, frame):
    # remembered as well as raised: landing in a weakref callback or a __del__ while a module
    # is imported, the KeyboardInterrupt is printed as "ignored" and the command went on (exit
    # 0); main() looks at the flag before the command starts
    SEEN.add("SIGINT")
    raise KeyboardInterrupt


def on_sigterm(signum, frame):
    # remembered as well as raised: a library that catches the exception in its own wait can
    # raise a plain KeyboardInterrupt in its place (Ray's ray.wait does), and it is still SIGTERM
    SEEN.add("SIGTERM")
    raise Terminated


def stop_behind(err: BaseException) -> KeyboardInterrupt | None:
    """The Ctrl-C or SIGTERM an error stands for, if any: an interrupt inside compiled code
    comes back wrapped (numba's dispatcher turns it into a SystemError whose cause is the
    KeyboardInterrupt), and it is still the user's stop, not a failure."""
    from ...core.causes import cause_of_kind

    stop = cause_of_kind(err, KeyboardInterrupt)
    return stop if isinstance(stop, KeyboardInterrupt) else None
