"""Options as a user gives them: one frozen dataclass per owner (a method, the tracker filter),
each field declared once with its default, its help and, for a number, its closed range (for a
text, its choices where they are fixed).

Everything a user sees of an option is read from that declaration: the `NAME:key=value`
parser and its errors, the nodes' ROS parameters (with native ranges that `ros2 param
describe` shows), the options an evaluation records and the table in docs/options.md. An
added option is one `option(...)` line in one dataclass."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, ClassVar, TypeVar

TYPES = {
    "float": (int, float),
    "int": (int,),
    "bool": (bool,),
    "str": (str,),
    "None": (type(None),),
    "tuple[str, ...]": (tuple, list),  # a node's string array
}
WORDS = {
    "float": "a number",
    "int": "an integer",
    "bool": "true or false",
    "str": "a text",
    "None": "null",
    "tuple[str, ...]": "a list of texts",
}

AnOptions = TypeVar("AnOptions", bound="Options")


@dataclass(frozen=True)
class Range:
    low: float
    high: float
    unit: str = ""

    def __str__(self) -> str:
        return f"from {self.low:g} to {self.high:g}" + (f" ({self.unit})" if self.unit else "")


def option(
    default: Any,
    help: str,
    low: float | None = None,
    high: float | None = None,
    unit: str = "",
    choices: tuple[str, ...] | None = None,
    experiment: bool = False,
) -> Any:
    """A dataclass field that is an option: its default, what it does, for a number the closed
    interval it must lie in (a number without one is refused by the tests), and for a text
    the values it may take, where they are fixed. `experiment`: kept only so that a lab note's
    figures can be measured again, not for users (docs/options.md lists these apart)."""
    bounds = None if low is None or high is None else Range(low, high, unit)
    metadata = {"help": help, "range": bounds, "choices": choices, "experiment": experiment}
    return dataclasses.field(default=default, metadata=metadata)


@dataclass(frozen=True)
class Option:
    """One option as read from its declaration."""

    name: str
    annotation: str  # as written: "float", "str | None", ...
    default: Any
    help: str
    range: Range | None
    choices: tuple[str, ...] | None = None  # a text's values, where they are fixed
    experiment: bool = False  # kept to measure a lab note's figures again, not for users

    @property
    def kinds(self) -> list[str]:
        return [part.strip() for part in self.annotation.split("|")]

    @property
    def types(self) -> tuple[type, ...]:
        return tuple(t for kind in self.kinds for t in TYPES.get(kind, (object,)))

    @property
    def numeric(self) -> bool:
        return any(kind in ("float", "int") for kind in self.kinds)

    def words(self) -> str:
        """What kind of value it takes: "a number", "a text or null"."""
        return " or ".join(dict.fromkeys(WORDS.get(kind, kind) for kind in self.kinds))

    def takes(self) -> str:
        """What the option takes, in words: "a number from 0 to 1 (metres)", "true or false"."""
        if self.choices:
            return "one of " + ", ".join(f"`{c}`" for c in self.choices)
        return f"{self.words()} {self.range}" if self.range is not None else self.words()

    def check(self, owner: str, value: object) -> None:
        """Raise ValueError naming the owner, the option, what it takes and the value, unless
        value fits."""
        prefix = f"{owner}: {self.name}"
        is_bool = isinstance(value, bool)
        if not isinstance(value, self.types) or (is_bool and bool not in self.types):
            raise ValueError(f"{prefix} takes {self.words()}, got {shown(value)}")
        if self.choices and isinstance(value, str) and value not in self.choices:
            raise ValueError(f"{prefix} must be one of {', '.join(self.choices)}, got {shown(value)}")
        if self.numeric and not is_bool and isinstance(value, (int, float)):
            bounds = self.range
            if not math.isfinite(value) or (bounds is not None and not bounds.low <= value <= bounds.high):
                raise ValueError(f"{prefix} must be {bounds or 'finite'}, got {shown(value)}")


def shown(value: object, limit: int = 80) -> str:
    """A value as an error quotes it: its repr, cut to `limit` characters (a 100 kB option value
    was echoed whole in a node's log)."""
    text = repr(value)
    return text if len(text) <= limit else f"{text[: limit - 25]}... ({len(text):,} characters)"


def _annotation(kind: object) -> str:
    """A field's type as written ("float", "str | None"), postponed or not."""
    return (
        kind if isinstance(kind, str) else getattr(kind, "__name__", str(kind)) if isinstance(kind, type) else str(kind)
    )


@dataclass(frozen=True)
class Options:
    """The base of every options dataclass: reading one from what a user gave, and what it
    holds as plain data. Subclasses declare fields with option()."""

    # what errors call the owner: "estimator 'ik'", "filter"
    owner: ClassVar[str] = "options"
    # whether options it has not are passed on to another owner (refined: its base's), which
    # checks them; parse() then leaves them, rest() gives them
    passes_on: ClassVar[bool] = False
    # what else its owner takes, named after its own in an unknown option's error
    others: ClassVar[str] = ""

    @classmethod
    def fields(cls) -> dict[str, Option]:
        """The options, by name, in declaration order (a subclass's after its base's)."""
        return {
            f.name: Option(
                f.name,
                _annotation(f.type),
                f.default,
                f.metadata.get("help", ""),
                f.metadata.get("range"),
                f.metadata.get("choices"),
                f.metadata.get("experiment", False),
            )
            for f in dataclasses.fields(cls)
        }

    @classmethod
    def parse(cls: type[AnOptions], given: dict[str, Any], owner: str | None = None) -> AnOptions:
        """The options given (by name) over the defaults; ValueError in one line for a name it
        has not or a value outside what it takes."""
        owner = owner or cls.owner
        known = cls.fields()
        unknown = [name for name in given if name not in known]
        if unknown and not cls.passes_on:
            names = ", ".join(known) or "none"
            raise ValueError(
                f"{owner} has no option {', '.join(map(repr, unknown))}; its options are {names}{cls.others}"
            )
        own = {name: value for name, value in given.items() if name in known}
        for name, value in own.items():
            known[name].check(owner, value)
        made = cls(**own)
        made.check_together()
        return made

    def check_together(self) -> None:
        """ValueError in one line where options that are each in range do not go together
        (a band's top under its bottom): run by parse, so before anything is made or loaded."""

    @classmethod
    def rest(cls, given: dict[str, Any]) -> dict[str, Any]:
        """The options given that are not this dataclass's (those it passes on)."""
        known = cls.fields()
        return {name: value for name, value in given.items() if name not in known}

    def as_dict(self) -> dict[str, Any]:
        """Every option's value, for a record (JSON)."""
        return dataclasses.asdict(self)
