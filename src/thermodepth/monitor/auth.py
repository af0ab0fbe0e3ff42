"""Who may use the monitor's HTTP server, and forged requests refused.

With a token (``http.token_file``, else ``THERMODEPTH_HTTP_TOKEN``), every route but
``/healthz``, the login page and its assets wants it: the API and ``/metrics`` as a bearer
header (``Authorization: Bearer TOKEN``), the pages through a login form (the token and the
operator's name) that sets a session cookie (HttpOnly, SameSite=Strict, Secure over TLS), the
live pictures and streams also as a query (``?token=``: the server asks for it only there,
:data:`~.http.LIVE_PICTURE`). Without a token (a monitor listening on loopback only)
everything is open.

Every request that changes something (a POST) must carry the session's CSRF token in
``X-CSRF-Token`` and a JSON body (``Content-Type: application/json``, which another site's
page cannot send without the browser asking first) -- unless it carries the bearer token
itself, which no other site's page can. Without a token the server's own CSRF token serves,
readable only by pages of its own origin (``/api/session``).
"""

from __future__ import annotations

import hmac
import os
import secrets
import threading
import time
from dataclasses import dataclass
from typing import Any

TOKEN_ENV = "THERMODEPTH_HTTP_TOKEN"
COOKIE = "thermodepth_session"
SESSION_S = 12 * 3600.0


@dataclass(frozen=True)
class Identity:
    """Who asks: by ``bearer`` token, the token as a ``query``, a login ``session`` (the
    operator's ``name``) or ``open`` (no token set); ``csrf``: the token its changes must
    carry (None: none needed)."""

    kind: str
    name: str | None = None
    csrf: str | None = None


class Auth:
    """The token, the sessions and the CSRF tokens of one server (module docstring);
    ``secure``: cookies only over TLS."""

    def __init__(self, token: str | None, secure: bool = False) -> None:
        self.token, self.secure = token, secure
        self.open_csrf = secrets.token_urlsafe(32)
        self._sessions: dict[str, tuple[str, str, float]] = {}  # id: name, csrf, until
        self._lock = threading.Lock()

    @classmethod
    def from_env(cls, token: str | None, secure: bool = False) -> Auth:
        """The token given, else ``THERMODEPTH_HTTP_TOKEN``'s (None: open)."""
        return cls(token or os.environ.get(TOKEN_ENV) or None, secure)

    def _bearer(self, headers: Any) -> bool:
        given = headers.get("authorization", "")
        return self.token is not None and hmac.compare_digest(
            given.encode(), f"Bearer {self.token}".encode()
        )

    def identity(self, headers: Any, cookies: Any, query: str | None = None) -> Identity | None:
        """Who a request is (None: nobody allowed); ``query``: the token given as a query,
        where the server takes one."""
        if self.token is None:
            return Identity("open", None, self.open_csrf)
        if self._bearer(headers):
            return Identity("bearer")
        if query is not None and hmac.compare_digest(query.encode(), self.token.encode()):
            return Identity("query")
        session = cookies.get(COOKIE)
        if session:
            with self._lock:
                found = self._sessions.get(session)
                if found is not None and found[2] > time.time():
                    return Identity("session", found[0], found[1])
                self._sessions.pop(session, None)
        return None

    def login(self, token: str, name: str) -> str | None:
        """A new session's id for the right token (None: refused)."""
        if self.token is None or not hmac.compare_digest(token.encode(), self.token.encode()):
            return None
        session = secrets.token_urlsafe(32)
        with self._lock:
            now = time.time()
            self._sessions = {k: v for k, v in self._sessions.items() if v[2] > now}
            self._sessions[session] = (name, secrets.token_urlsafe(32), now + SESSION_S)
        return session

    def logout(self, session: str | None) -> None:
        with self._lock:
            self._sessions.pop(session or "", None)

    @staticmethod
    def forged(who: Identity, headers: Any) -> str | None:
        """Why a changing request cannot be taken as its sender's (None: it can)."""
        if who.csrf is None:
            return None
        if not headers.get("content-type", "").startswith("application/json"):
            return "expected a JSON body (Content-Type: application/json)"
        if not hmac.compare_digest(headers.get("x-csrf-token", "").encode(), who.csrf.encode()):
            return "missing or wrong X-CSRF-Token (GET /api/session gives it)"
        return None
