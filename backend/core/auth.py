"""API tokens and roles: tokens are random 256-bit strings stored as their sha256 hash.

Why sha256 and not a slow password hash: a token carries 256 bits of entropy from ``secrets``, so
a stolen hash cannot be brute-forced however fast the hash is; a fast, unsalted hash lets each
request find its token by an indexed equality lookup instead of running a KDF per request.

Revocation reaches every process that shares the database: a revocation here (DELETE /tokens/{id})
forgets the token at once; one made elsewhere (``acs-twin token revoke`` is another process) is seen by
the revocation watch, which asks the database every REVOCATION_POLL_S which of the tokens this process
holds (cached, or with open WebSockets and monitor sessions) are revoked: one indexed query on the
primary key, none when nothing is held. Revoked tokens' sessions close within that period.
"""

from __future__ import annotations

import hashlib
import logging
import secrets
import threading
from collections.abc import Callable
from dataclasses import dataclass
from enum import IntEnum

from backend.core.token_repository import TokenRepository

__all__ = ["Role", "Principal", "new_token", "token_sha256", "Authenticator", "TOKEN_PREFIX"]

TOKEN_PREFIX = "acs_"
REVOCATION_POLL_S = 0.25  # a revocation by another process closes sessions within this (+ one query)

log = logging.getLogger(__name__)


class Role(IntEnum):
    """Ordered roles: reads need viewer, state changes operator, token management admin."""

    viewer = 1
    operator = 2
    admin = 3

    @classmethod
    def parse(cls, name: str) -> Role:
        """Role from its name; ValueError naming the field ``role`` otherwise."""
        try:
            return cls[name]
        except KeyError:
            raise ValueError(f"role: must be one of viewer, operator, admin, got {name!r}") from None


@dataclass(frozen=True)
class Principal:
    """Who is calling: token id (None when auth is off), name and role."""

    token_id: int | None
    name: str
    role: Role


LOCAL_ADMIN = Principal(token_id=None, name="local (auth disabled)", role=Role.admin)


def new_token() -> str:
    """A fresh token: prefix + 43 URL-safe characters (256 bits from the OS CSPRNG)."""
    return TOKEN_PREFIX + secrets.token_urlsafe(32)


def token_sha256(token: str) -> str:
    """Hex sha256 of a token, the only form stored at rest."""
    return hashlib.sha256(token.encode("utf-8")).hexdigest()


class Authenticator:
    """Resolves bearer tokens to principals, caching hits in memory until a revocation."""

    def __init__(self, tokens: TokenRepository, enabled: bool) -> None:
        self._tokens, self.enabled = tokens, enabled
        self._cache: dict[str, Principal] = {}
        self._lock = threading.Lock()
        self._watchers: dict[int, dict[int, Callable[[], object]]] = {}
        self._poll_stop = threading.Event()
        self._poller: threading.Thread | None = None

    def watch(self, principal: Principal, on_revoke: Callable[[], object]) -> Callable[[], None]:
        """Call ``on_revoke`` (from any thread) when the principal's token is revoked; returns the unwatch."""
        if principal.token_id is None:
            return lambda: None
        key, token_id = id(on_revoke), principal.token_id
        with self._lock:
            self._watchers.setdefault(token_id, {})[key] = on_revoke

        def unwatch() -> None:
            with self._lock:
                self._watchers.get(token_id, {}).pop(key, None)

        return unwatch

    def cached(self, token: str | None) -> Principal | None:
        """The principal if known without a database lookup (auth off, or a cached token)."""
        if not self.enabled:
            return LOCAL_ADMIN
        if not token:
            return None
        with self._lock:
            return self._cache.get(token_sha256(token))

    def resolve(self, token: str | None) -> Principal | None:
        """The principal owning ``token``; None when missing, unknown or revoked."""
        cached = self.cached(token)
        if cached is not None or not token:
            return cached
        digest = token_sha256(token)
        row = self._tokens.find_active(digest)
        if row is None:
            return None
        principal = Principal(token_id=row.id, name=row.name, role=Role.parse(row.role))
        with self._lock:
            self._cache[digest] = principal
        return principal

    def forget(self, token_id: int) -> None:
        """Drop a revoked token from the cache and close what it opened (WebSockets, monitor sessions)."""
        with self._lock:
            for digest in [d for d, p in self._cache.items() if p.token_id == token_id]:
                del self._cache[digest]
            watchers = list(self._watchers.pop(token_id, {}).values())
        for on_revoke in watchers:
            on_revoke()

    def held_token_ids(self) -> set[int]:
        """Tokens this process holds: cached for requests, or watched by open WebSockets and monitor sessions."""
        with self._lock:
            cached = {p.token_id for p in self._cache.values() if p.token_id is not None}
            return cached | {token_id for token_id, watchers in self._watchers.items() if watchers}

    def check_revocations(self) -> set[int]:
        """Forget every held token the database says is revoked (by any process); the ids forgotten."""
        held = self.held_token_ids()
        revoked = self._tokens.revoked_among(held) if held else set()
        for token_id in revoked:
            self.forget(token_id)
        return revoked

    def start_revocation_watch(self, period_s: float = REVOCATION_POLL_S) -> None:
        """Check the database for revocations every ``period_s`` in a daemon thread (no-op with auth off)."""
        if not self.enabled or self._poller is not None:
            return
        self._poll_stop.clear()
        self._poller = threading.Thread(
            target=self._watch_revocations, args=(period_s,), name="revocation-watch", daemon=True
        )
        self._poller.start()

    def stop_revocation_watch(self) -> None:
        """Stop the revocation watch thread."""
        self._poll_stop.set()
        if self._poller is not None:
            self._poller.join(timeout=5.0)
            self._poller = None

    def _watch_revocations(self, period_s: float) -> None:
        while not self._poll_stop.wait(period_s):
            try:
                self.check_revocations()
            except Exception:  # a database hiccup must not end the watch: the next period asks again
                log.warning("revocation watch: database check failed", exc_info=True)

    def issue(self, name: str, role: Role) -> tuple[int, str]:
        """Create a token, store its hash; returns (id, plain token) — shown once, never stored."""
        from telemetry.archive import NAME_MAX  # here: the archive's import is ~0.3 s, a token is issued rarely

        if not name.strip():
            raise ValueError("name: must not be empty")
        if len(name) > NAME_MAX:  # the archive records it as uploaded_by / actor, in varchar(NAME_MAX) columns
            raise ValueError(f"name: at most {NAME_MAX} characters (the archive's actor names), got {len(name)}")
        token = new_token()
        row = self._tokens.add(name=name, role=role.name, token_sha256=token_sha256(token))
        return row.id, token
