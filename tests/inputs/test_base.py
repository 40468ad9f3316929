"""The Input contract: what an input must define, what it gets by default, how it is named."""

from __future__ import annotations

import logging

import pytest

from smoothjog.inputs.base import KIND_NOUNS, Input, InputHandle, LeaseExpired, kind_noun


class Pad(Input):
    """The smallest complete input."""

    name = "test pad"
    kind = "gamepad"
    lease_s = 0.15

    async def run(self, handle: InputHandle) -> None:
        return None


def test_an_input_without_run_cannot_be_made() -> None:
    class Incomplete(Input):
        name = "nothing"
        kind = "script"
        lease_s = None

    with pytest.raises(TypeError, match="abstract"):
        Incomplete()  # type: ignore[abstract]


def test_the_default_notice_is_logged_in_words(caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.WARNING, logger="smoothjog.inputs.base"):
        Pad().notice(LeaseExpired(silent_s=0.2, lease_s=0.15))
    assert caplog.messages == [
        "gamepad test pad: jog stopped: nothing heard from this input for 200 ms "
        "(the dead-man window is 150 ms)"
    ]


@pytest.mark.parametrize(
    ("kind", "noun"),
    [
        ("web", "pendant"),
        ("gamepad", "gamepad"),
        ("handwheel", "handwheel"),
        ("spacemouse", "SpaceMouse"),
        ("cncjs", "input"),
    ],
)
def test_messages_name_an_input_by_its_kind(kind: str, noun: str) -> None:
    assert kind_noun(kind) == noun


def test_every_documented_kind_has_a_noun() -> None:
    assert set(KIND_NOUNS) == {"web", "gamepad", "keyboard", "handwheel", "spacemouse", "script"}


def test_every_device_decoder_is_of_a_kind_with_a_noun() -> None:
    from smoothjog.inputs.kinds import DECODERS

    assert {d.kind for d in DECODERS} <= set(KIND_NOUNS)
