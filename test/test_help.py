"""Every command's --help, walked: each option and argument has help text, a default is said
at most once (and not when there is none), and a name the help gives in capitals is one the
usage line shows."""

import argparse
import re

import pytest

from sparse_body.cli import build_parser


def _commands():
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return sub.choices


@pytest.mark.parametrize("name", sorted(_commands()))
def test_every_option_has_help_with_its_default_said_once_and_names_as_in_the_usage(name):
    command = _commands()[name]
    usage = command.format_usage()
    formatter = command._get_formatter()
    arguments = {a.dest.upper() for a in command._actions} | {str(a.metavar) for a in command._actions if a.metavar}
    for action in command._actions:
        if isinstance(action, argparse._HelpAction):
            continue
        label = action.option_strings[0] if action.option_strings else action.dest
        assert action.help, f"{name} {label}: no help text"
        text = formatter._expand_help(action) if action.help else ""
        assert text.count("default") <= 1, f"{name} {label}: {text!r}"
        assert "(default: None)" not in text and "(default: False)" not in text, f"{name} {label}: {text!r}"
        # an argument named in capitals is named as the usage line names it (the help said
        # BAG_OUT, its dest, for the argument the usage calls OUT)
        for word in re.findall(r"\b[A-Z][A-Z_]{1,}\b", action.help):
            if word in arguments:
                assert re.search(rf"\b{word}\b", usage), f"{name} {label}: {word} is not in the usage line"


def test_the_readme_is_short_and_names_no_maintainers_folder():
    """A newcomer reads it in one sitting: at most 250 lines (it reached 289), and no folder
    only the maintainers have."""
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    assert len(text.splitlines()) <= 250, len(text.splitlines())
    assert "../shared" not in text and "Maintainers" not in text
