"""The device kinds smoothjog knows: adding one is a new decoder file and one line here.

The order is the order of matching: a device goes to the first decoder of its transport that
takes it, so the specific kinds (by USB ids) come before the general ones (by capabilities),
and the knob (a device with a few media keys) before the keyboard.
"""

from __future__ import annotations

from typing import Final

from smoothjog.core.errors import ConfigError
from smoothjog.inputs.device import Decoder
from smoothjog.inputs.gamepad import GamepadDecoder
from smoothjog.inputs.keyboard import KeyboardDecoder
from smoothjog.inputs.knob import KnobDecoder
from smoothjog.inputs.shuttle import ShuttleDecoder, ShuttleEvdevDecoder
from smoothjog.inputs.spacemouse import SpaceMouseDecoder, SpaceMouseEvdevDecoder
from smoothjog.inputs.whb04b import Whb04bDecoder

DECODERS: Final[tuple[type[Decoder], ...]] = (
    Whb04bDecoder,
    ShuttleDecoder,
    SpaceMouseDecoder,
    ShuttleEvdevDecoder,
    SpaceMouseEvdevDecoder,
    GamepadDecoder,
    KnobDecoder,
    KeyboardDecoder,
)

KIND_NAMES: Final = tuple(d.name for d in DECODERS)


def decoder_named(name: str, *, where: str = "--input-kind") -> type[Decoder]:
    """The decoder class of a kind name; ConfigError naming `where` for an unknown one."""
    for decoder in DECODERS:
        if decoder.name == name:
            return decoder
    raise ConfigError(
        f"{where}: unknown device kind {name!r}; the kinds are {', '.join(KIND_NAMES)}"
    )
