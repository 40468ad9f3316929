"""CNCjs tokens: the secret read from its config, the signature, and every way it can fail."""

from __future__ import annotations

import base64
import hashlib
import hmac
import json
from pathlib import Path

import pytest

from smoothjog.links.cncjs_auth import (
    PENDANT_NAME,
    SECRET_ENV,
    CncjsAuthError,
    check_token,
    make_token,
    read_cncjs_config,
    refusal_sentence,
    sign_token,
    token_payload,
)

SECRET = "$2a$10$abcdefghijklmnopqrstuv"
NOW = 1_800_000_000.0


def _verify(token: str, secret: str) -> dict[str, object]:
    """An independent HS256 check, as CNCjs's jsonwebtoken does it."""
    head, body, sig = token.split(".")
    mac = hmac.new(secret.encode(), f"{head}.{body}".encode(), hashlib.sha256).digest()
    assert base64.urlsafe_b64encode(mac).rstrip(b"=").decode() == sig
    header = json.loads(base64.urlsafe_b64decode(head + "=" * (-len(head) % 4)))
    assert header == {"alg": "HS256", "typ": "JWT"}
    return token_payload(token)


def _config(tmp_path: Path, **data: object) -> Path:
    path = tmp_path / "cncrc.json"
    path.write_text(json.dumps({"secret": SECRET, "users": [], **data}))
    return path


def test_a_token_is_signed_with_the_config_secret(tmp_path: Path) -> None:
    token = make_token(config_path=_config(tmp_path), now_s=NOW)
    claims = _verify(token, SECRET)
    assert claims["id"] == ""
    assert claims["name"] == PENDANT_NAME
    assert claims["iat"] == int(NOW)
    assert claims["exp"] > NOW


def test_the_secret_can_come_from_the_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(SECRET_ENV, "from-env")
    _verify(make_token(now_s=NOW), "from-env")


def test_a_named_config_wins_over_the_environment(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv(SECRET_ENV, "from-env")
    _verify(make_token(config_path=_config(tmp_path), now_s=NOW), SECRET)


def test_a_missing_config_says_where_and_what_to_do(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.delenv(SECRET_ENV, raising=False)
    with pytest.raises(CncjsAuthError, match=r"no CNCjs config at .*nope.*--cncjs-config"):
        make_token(config_path=tmp_path / "nope")


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("{not json", "is not JSON"),
        ("{}", "has no secret yet"),
        ('{"secret": ""}', "has no secret yet"),
        ("[1, 2]", "has no secret yet"),
    ],
)
def test_a_broken_config_is_refused_in_words(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "cncrc.json"
    path.write_text(text)
    with pytest.raises(CncjsAuthError, match=message):
        read_cncjs_config(path)


def test_with_users_configured_a_user_must_be_named(tmp_path: Path) -> None:
    users = [
        {"id": "u1", "name": "alice", "enabled": True},
        {"id": "u2", "name": "bob", "enabled": False},
    ]
    path = _config(tmp_path, users=users)
    with pytest.raises(CncjsAuthError, match=r"users configured .*\(alice\).*--cncjs-user"):
        make_token(config_path=path, now_s=NOW)
    with pytest.raises(CncjsAuthError, match="no enabled user 'bob'"):
        make_token(config_path=path, user="bob", now_s=NOW)
    claims = _verify(make_token(config_path=path, user="alice", now_s=NOW), SECRET)
    assert (claims["id"], claims["name"]) == ("u1", "alice")


def test_a_given_token_is_used_as_it_is_unless_expired() -> None:
    good = sign_token("s", {"id": "", "name": "x", "exp": NOW + 60})
    assert make_token(token=f" {good}\n", now_s=NOW) == good
    old = sign_token("s", {"id": "", "name": "x", "exp": NOW - 60})
    with pytest.raises(CncjsAuthError, match="expired on 2027-01-15"):
        check_token(old, NOW)
    forever = sign_token("s", {"id": "", "name": "x"})
    assert check_token(forever, NOW) == forever


@pytest.mark.parametrize("bad", ["", "abc", "a.b", "a.!!!.c", "a.bm90IGpzb24.c", "a.WzFd.c"])
def test_a_token_that_is_not_one_is_refused(bad: str) -> None:
    with pytest.raises(CncjsAuthError, match="token"):
        check_token(bad, NOW)


@pytest.mark.parametrize(
    ("payload", "words"),
    [
        ({"message": "no token provided", "code": "credentials_required"}, "got none"),
        ({"message": "invalid signature", "code": "invalid_token"}, "not signed with this"),
        ({"message": "jwt expired", "code": "invalid_token"}, "has expired"),
        (
            "Unauthorized user: user.id=, user.name=smoothjog",
            "users configured, give --cncjs-user",
        ),
        ({"message": "something new"}, "refused the connection: something new"),
        (None, "no reason given"),
    ],
)
def test_each_refusal_has_its_sentence(payload: object, words: str) -> None:
    assert words in refusal_sentence(payload, "http://127.0.0.1:8000")
