"""One TOML table being read: typed getters that check bounds, and a check for unread keys.

The config file (smoothjog.config) and every device decoder's options (inputs/) read their
values through it, so each error names the file, the section and the key, says what is wrong
and how to fix it, and a key nothing reads (most often a typo) is an error too.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from smoothjog.core.errors import ConfigError
from smoothjog.core.units import ALL_AXES


class Table:
    """One TOML table being read: typed getters with bounds, and a check for unread keys."""

    def __init__(self, data: Mapping[str, Any], section: str, source: str) -> None:
        """Wrap the table `section` of the file `source`."""
        self.data = data
        self.section = section
        self.source = source
        self._read: set[str] = set()

    def error(self, key: str, problem: str) -> ConfigError:
        """A ConfigError naming the file, section and key."""
        return ConfigError(f"{self.source}: [{self.section}] {key} {problem}")

    def _take(self, key: str) -> Any:
        """The raw value of key, marking it read (None when absent)."""
        self._read.add(key)
        return self.data.get(key)

    def raw(self, key: str) -> Any:
        """The value of key as written (None when absent), marked read: for a getter of the
        caller's own (a list of names, a list of any length), which checks it itself."""
        return self._take(key)

    def number(
        self,
        key: str,
        default: float,
        *,
        above: float | None = None,
        at_least: float | None = None,
        at_most: float | None = None,
    ) -> float:
        """A number within the given bounds."""
        value = self._take(key)
        if value is None:
            return default
        return self.check_number(key, value, above=above, at_least=at_least, at_most=at_most)

    def check_number(
        self,
        key: str,
        value: Any,
        *,
        above: float | None = None,
        at_least: float | None = None,
        at_most: float | None = None,
    ) -> float:
        """Check a value is a finite number within the bounds."""
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.error(key, f"= {value!r} is not a number: write e.g. {key} = 1.5")
        number = float(value)
        if not math.isfinite(number):
            raise self.error(key, f"= {value!r} is not a finite number")
        if above is not None and not number > above:
            raise self.error(key, f"= {value!r} must be above {above:g}")
        if at_least is not None and number < at_least:
            raise self.error(key, f"= {value!r} must be at least {at_least:g}")
        if at_most is not None and number > at_most:
            raise self.error(key, f"= {value!r} must be at most {at_most:g}")
        return number

    def integer(self, key: str, default: int, *, at_least: int, at_most: int) -> int:
        """A whole number within [at_least, at_most]."""
        value = self._take(key)
        if value is None:
            return default
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.error(
                key, f"= {value!r} is not a whole number: write e.g. {key} = {default}"
            )
        if not at_least <= value <= at_most:
            raise self.error(key, f"= {value} must be from {at_least} to {at_most}")
        return value

    def text(self, key: str, default: str | None) -> str | None:
        """A non-empty string."""
        value = self._take(key)
        if value is None:
            return default
        if not isinstance(value, str):
            raise self.error(key, f"= {value!r} is not a string: put it in quotes")
        if not value.strip():
            raise self.error(key, "is empty: give a value or remove the key")
        return value

    def choice(self, key: str, default: str, choices: Sequence[str]) -> str:
        """A string from a fixed set."""
        value = self.text(key, default)
        assert value is not None  # a default is given
        if value not in choices:
            raise self.error(key, f"= {value!r} is not one of {', '.join(choices)}")
        return value

    def flag(self, key: str, default: bool) -> bool:
        """A boolean."""
        value = self._take(key)
        if value is None:
            return default
        if not isinstance(value, bool):
            raise self.error(key, f"= {value!r} is not true or false")
        return value

    def table(self, key: str) -> Mapping[str, Any]:
        """A nested table (empty when absent)."""
        value = self._take(key)
        if value is None:
            return {}
        if not isinstance(value, dict):
            raise self.error(key, f"= {value!r} is not a table: write {key} = {{ x = 1 }}")
        return value

    def numbers(self, key: str) -> tuple[float, ...]:
        """A required list of 1 to 9 numbers."""
        value = self._take(key)
        if value is None:
            raise self.error(key, f"is missing: give one number per axis, e.g. {key} = [0, 0, 0]")
        if not isinstance(value, list) or not 1 <= len(value) <= len(ALL_AXES):
            raise self.error(
                key, f"= {value!r} is not a list of 1 to {len(ALL_AXES)} numbers (one per axis)"
            )
        return tuple(self.check_number(key, item) for item in value)

    def finish(self) -> None:
        """Raise for the first key nothing read (a probable typo)."""
        unknown = sorted(set(self.data) - self._read)
        if unknown:
            known = ", ".join(sorted(self._read))
            raise ConfigError(
                f"{self.source}: unknown key {unknown[0]!r} in [{self.section}]: the known keys"
                f" are {known} (check the spelling)"
            )
