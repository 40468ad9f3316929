"""The one exception tree of smoothjog; every layer raises a subclass of SmoothjogError."""

from __future__ import annotations


class SmoothjogError(Exception):
    """Root of every error smoothjog raises on purpose; its message is fit to show a user."""


class CoreError(SmoothjogError):
    """A pure-core refusal (bad jog request, bad number, impossible geometry)."""


class JogBuildError(CoreError):
    """A `$J=` line could not be built because Grbl would reject it or it would be dangerous."""


class ConfigError(SmoothjogError):
    """A configuration file or value is wrong; the message names the file and the key."""


class LinkError(SmoothjogError):
    """A transport failed: the port or socket could not be opened, or the peer went away."""


class ConnectError(SmoothjogError):
    """The peer did not answer like a Grbl-family controller within the time allowed."""


class SimError(SmoothjogError):
    """The simulator was given something it cannot model (unknown profile, bad setting file)."""


class EngineError(SmoothjogError):
    """The jog engine hit a condition it cannot continue from without the user."""


class InputRefused(SmoothjogError):  # noqa: N818 -- a refusal, not a fault; inputs catch it by name
    """An input's intent was refused: not the controlling input, jogging disabled, or invalid."""
