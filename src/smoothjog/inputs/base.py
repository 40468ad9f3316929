"""The Input contract: what every device or script that produces jog intents implements.

An input reads its device and submits intents through the `InputHandle` the arbiter gives it;
the arbiter (smoothjog.authority.arbiter) decides which input controls, watches the dead-man
lease and stops the machine when the controlling input goes away. Adding a device is adding one
file here with one `Input` subclass; nothing in this package knows of Grbl, links or sessions.

Rules every input follows:
- `run(handle)` reads until the device ends; returning or raising both mean "the input is gone"
  (the arbiter detaches it, stopping the machine if it was driving it).
- An input with `lease_s` repeats its continuous intent (or calls `alive()`) more often than
  every `lease_s` while a jog is held; silence for `lease_s` stops the machine.
- `submit` raises `InputRefused` in words; an input shows the words to its user if it can.
"""

from __future__ import annotations

import logging
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Final, Protocol

from smoothjog.core.intents import Intent

log = logging.getLogger(__name__)

#: The kinds of input, as `Input.kind` names them; the noun is how a message refers to one.
KIND_NOUNS: Final = {
    "web": "pendant",
    "gamepad": "gamepad",
    "keyboard": "keyboard",
    "handwheel": "handwheel",
    "spacemouse": "SpaceMouse",
    "script": "script",
}


def kind_noun(kind: str) -> str:
    """How user-facing text names an input of this kind ("pendant" for "web")."""
    return KIND_NOUNS.get(kind, "input")


@dataclass(frozen=True)
class LeaseExpired:
    """The arbiter stopped this input's held jog: nothing came from it for silent_s (> lease_s)."""

    silent_s: float
    lease_s: float

    @property
    def text(self) -> str:
        """The notice in words, for an input with no wording of its own."""
        return (
            f"jog stopped: nothing heard from this input for {self.silent_s * 1000:.0f} ms "
            f"(the dead-man window is {self.lease_s * 1000:.0f} ms)"
        )


#: What the arbiter tells an input about its own jog (a union as more notices appear).
Notice = LeaseExpired


class InputHandle(Protocol):
    """An attached input's one way to the machine; every call returns at once."""

    def submit(self, intent: Intent) -> None:
        """Hand the arbiter a new intent; raises InputRefused saying why it was not taken."""
        ...

    def alive(self) -> None:
        """Heartbeat: renew the dead-man lease of the held jog without changing the intent."""
        ...

    def take_control(self) -> None:
        """Become the controlling input; raises InputRefused while another holds a jog."""
        ...

    @property
    def in_control(self) -> bool:
        """True while this input is the one that drives the machine."""
        ...

    def detach(self) -> None:
        """Leave: stops the machine if this input was driving it; later submits are refused."""
        ...


class Input(ABC):
    """A source of jog intents: a device, a page, a script."""

    #: Who this is, for logs and messages (e.g. "gamepad Logitech F310", "#2 192.168.1.20").
    name: str
    #: What it is: "web", "gamepad", "keyboard", "handwheel", "spacemouse", "script"
    #: (see KIND_NOUNS).
    kind: str
    #: The dead-man window (s) a held continuous jog from this input needs, or None for an
    #: input that cannot go silent mid-jog (a script, a local keyboard that reports key-up).
    lease_s: float | None

    @abstractmethod
    async def run(self, handle: InputHandle) -> None:
        """Read the device and submit intents through handle until the device ends."""

    def notice(self, notice: Notice) -> None:
        """Show the user what the arbiter did to this input's jog; by default it is logged."""
        log.warning("%s %s: %s", self.kind, self.name, notice.text)


__all__ = ["KIND_NOUNS", "Input", "InputHandle", "LeaseExpired", "Notice", "kind_noun"]
