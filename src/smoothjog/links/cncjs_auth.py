"""Tokens for CNCjs: read its secret, sign a pendant token, and say in words why one was refused.

CNCjs admits a socket.io client only with a JSON Web Token (HS256) signed with the `secret` string
of the config file it was started with (`~/.cncrc` unless its `-c` option names another). While
no users are configured any `id`/`name` passes; with users, the token must name an enabled one.
docs/cncjs.md has the steps a user takes and what was measured of CNCjs.

Signing is ten lines of hmac and base64, so no JWT library is needed.
"""

from __future__ import annotations

import base64
import binascii
import hashlib
import hmac
import json
import os
import time
from dataclasses import dataclass
from pathlib import Path

from smoothjog.core.errors import LinkError

#: Where CNCjs keeps its config (and so its secret) unless started with `-c FILE`.
DEFAULT_CNCJS_CONFIG = "~/.cncrc"
#: The environment variable the CNCjs pendants read a secret from.
SECRET_ENV = "CNCJS_SECRET"
#: How long a token smoothjog signs stays valid; it signs a new one for every connection.
TOKEN_LIFETIME_S = 24 * 3600.0
#: The name smoothjog's tokens carry when no users are configured.
PENDANT_NAME = "smoothjog"


class CncjsAuthError(LinkError):
    """No token could be made or CNCjs refused the one given; the message says what to do."""


@dataclass(frozen=True, slots=True)
class CncjsUser:
    """One enabled user of a CNCjs config."""

    id: str
    name: str


def _b64(data: bytes) -> str:
    return base64.urlsafe_b64encode(data).rstrip(b"=").decode("ascii")


def _unb64(text: str) -> bytes:
    return base64.urlsafe_b64decode(text + "=" * (-len(text) % 4))


def sign_token(secret: str, payload: dict[str, object]) -> str:
    """An HS256 JSON Web Token of payload, signed with secret."""
    header = {"alg": "HS256", "typ": "JWT"}
    head = _b64(json.dumps(header, separators=(",", ":")).encode())
    body = _b64(json.dumps(payload, separators=(",", ":")).encode())
    mac = hmac.new(secret.encode(), f"{head}.{body}".encode(), hashlib.sha256).digest()
    return f"{head}.{body}.{_b64(mac)}"


def token_payload(token: str) -> dict[str, object]:
    """The claims of a token (not verified: only CNCjs knows its secret); CncjsAuthError if
    it is not a token at all."""
    parts = token.split(".")
    if len(parts) != 3:
        raise CncjsAuthError(
            "the CNCjs token given is not a JSON Web Token (three parts joined by dots): copy it"
            " whole, or leave --cncjs-token out to sign one with the secret of CNCjs's config"
        )
    try:
        claims = json.loads(_unb64(parts[1]))
    except (binascii.Error, UnicodeDecodeError, ValueError):
        raise CncjsAuthError(
            "the CNCjs token given does not decode: copy it whole, or leave --cncjs-token out"
            " to sign one with the secret of CNCjs's config"
        ) from None
    if not isinstance(claims, dict):
        raise CncjsAuthError("the CNCjs token given carries no claims: it is not a CNCjs token")
    return claims


def check_token(token: str, now_s: float | None = None) -> str:
    """Return token if it is well formed and not expired; CncjsAuthError in words if not."""
    claims = token_payload(token)
    exp = claims.get("exp")
    now = time.time() if now_s is None else now_s
    if isinstance(exp, int | float) and exp <= now:
        when = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime(exp))
        raise CncjsAuthError(
            f"the CNCjs token given expired on {when}: make a new one, or leave --cncjs-token"
            " out to sign one with the secret of CNCjs's config"
        )
    return token


@dataclass(frozen=True, slots=True)
class CncjsConfig:
    """What smoothjog needs of a CNCjs config file: its secret and its enabled users."""

    path: Path
    secret: str
    users: tuple[CncjsUser, ...]


def read_cncjs_config(path: str | os.PathLike[str] = DEFAULT_CNCJS_CONFIG) -> CncjsConfig:
    """Read CNCjs's config file; CncjsAuthError naming the file and the fix if it cannot."""
    where = Path(path).expanduser()
    fix = (
        "give --cncjs-config with the file CNCjs was started with (its -c option; ~/.cncrc of"
        " the user running CNCjs by default), or a token with --cncjs-token"
    )
    try:
        text = where.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise CncjsAuthError(f"no CNCjs config at {where}: {fix}") from None
    except OSError as exc:
        raise CncjsAuthError(
            f"cannot read the CNCjs config {where}: {exc.strerror}; {fix}"
        ) from None
    try:
        data = json.loads(text)
    except ValueError as exc:
        raise CncjsAuthError(f"the CNCjs config {where} is not JSON ({exc}); {fix}") from None
    secret = data.get("secret") if isinstance(data, dict) else None
    if not isinstance(secret, str) or not secret:
        raise CncjsAuthError(
            f"the CNCjs config {where} has no secret yet (CNCjs writes one when it first starts):"
            f" start CNCjs once, or {fix}"
        )
    users = []
    for item in data.get("users") or ():
        if isinstance(item, dict) and item.get("enabled", True) is not False:
            users.append(CncjsUser(str(item.get("id", "")), str(item.get("name", ""))))
    return CncjsConfig(where, secret, tuple(users))


def make_token(
    *,
    token: str | None = None,
    config_path: str | os.PathLike[str] | None = None,
    user: str | None = None,
    now_s: float | None = None,
) -> str:
    """The token to connect with: the one given, else one signed with the config's secret.

    The secret comes from $CNCJS_SECRET when set and no config file is named, else from the
    config file. With users configured the token names the one asked for (by name or id).
    """
    if token is not None:
        return check_token(token.strip(), now_s)
    now = int(time.time() if now_s is None else now_s)
    env_secret = os.environ.get(SECRET_ENV)
    users: tuple[CncjsUser, ...]
    if config_path is None and env_secret:
        secret, users, where = env_secret, (), f"${SECRET_ENV}"
    else:
        config = read_cncjs_config(config_path or DEFAULT_CNCJS_CONFIG)
        secret, users, where = config.secret, config.users, str(config.path)
    ident = {"id": "", "name": PENDANT_NAME}
    if users:
        names = ", ".join(u.name or u.id for u in users)
        if user is None:
            raise CncjsAuthError(
                f"CNCjs has users configured in {where} ({names}), so a token must name one:"
                " give --cncjs-user NAME"
            )
        chosen = [u for u in users if user in (u.name, u.id)]
        if not chosen:
            raise CncjsAuthError(
                f"CNCjs has no enabled user {user!r} in {where}; its users are: {names}"
            )
        ident = {"id": chosen[0].id, "name": chosen[0].name}
    elif user is not None:
        ident = {"id": "", "name": user}
    claims: dict[str, object] = {**ident, "iat": now, "exp": now + int(TOKEN_LIFETIME_S)}
    return sign_token(secret, claims)


def refusal_sentence(message: object, url: str) -> str:
    """What CNCjs's connect_error payload means, as a sentence with the fix."""
    text = message.get("message", "") if isinstance(message, dict) else str(message or "")
    text = str(text)
    if "no token" in text or "credentials_required" in text:
        return (
            f"CNCjs at {url} wants a token and got none: smoothjog signs one with the secret of"
            " CNCjs's config (--cncjs-config) or uses --cncjs-token"
        )
    if "invalid signature" in text:
        return (
            f"CNCjs at {url} refused the token: it is not signed with this CNCjs's secret; give"
            " --cncjs-config the file this CNCjs was started with (its -c option), or a token"
            " this CNCjs made"
        )
    if "expired" in text:
        return f"CNCjs at {url} refused the token: it has expired; make a new one"
    if "Unauthorized user" in text:
        return (
            f"CNCjs at {url} refused the token's user ({text}): CNCjs has users configured, give"
            " --cncjs-user with one of them"
        )
    return f"CNCjs at {url} refused the connection: {text or 'no reason given'}"
