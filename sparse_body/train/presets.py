"""Named training configurations as data (as nanoGPT's config files): each configuration class
lists its presets in PRESETS, a name -> the fields it changes, one commented knob a line;
"base" starts a preset from another one instead of the defaults."""

from __future__ import annotations

from dataclasses import replace
from typing import Any, ClassVar, TypeVar

P = TypeVar("P", bound="Presets")


class Presets:
    KIND: ClassVar[str] = "training"  # what the configuration configures, for the error
    PRESETS: ClassVar[dict[str, dict[str, Any]]] = {}

    @classmethod
    def named(cls: type[P], name: str) -> P:
        if name not in cls.PRESETS:
            raise ValueError(f"unknown {cls.KIND} configuration {name!r} ({', '.join(cls.PRESETS)})")
        fields = dict(cls.PRESETS[name])
        base = fields.pop("base", None)
        start: Any = cls.named(base) if base else cls()  # (a dataclass: each subclass is one)
        return replace(start, **fields)
