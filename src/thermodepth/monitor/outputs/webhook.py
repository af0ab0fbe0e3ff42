"""A webhook notification target (``notify: [{kind: webhook, ...}]``): each event a JSON POST,
delivered from the outbox (:mod:`.notify`), over the standard library's HTTP client (urllib:
no dependency for one POST).

The body is the event as ``/api/events`` gives it (with ``links`` when ``http.public_url`` is
set); a digest is ``{"digest": true, "count": N, "events": [...]}``. Headers:

- ``X-Thermodepth-Signature: sha256=HEX``: the HMAC-SHA256 of the exact body bytes keyed with
  the secret (the first line of ``secret_file``), as the receiver checks it
  (:func:`signature`);
- ``X-Thermodepth-Event-Id``: the event's id (``digest-FIRST-LAST`` for a digest): at least
  once means a receiver may get one again, this id lets it drop the repeat.

A 2xx is delivered; a 5xx, 429, 408, a refused or timed-out connection are retried; any other
answer (a 4xx, a redirect: a POST is not followed) is refused for good.

A scheduled inspection report (:mod:`..reports`) is a POST of its own, signed the same way:
``{"report": {"file", "path", "from_utc", "to_utc", "period", "summary", "link"}}`` (the
file stays on the monitor's disk; ``link`` to it when ``http.public_url`` is set), its id
header ``report-FILE``.
"""

from __future__ import annotations

import hashlib
import hmac
import json
import urllib.error
import urllib.request
from pathlib import Path
from typing import Any

from ... import __version__
from ...app.report import Period
from ..config import WebhookConfig, first_line
from .base import OutputContext
from .notify import DeliveryError, Notifier

SIGNATURE_HEADER = "X-Thermodepth-Signature"
EVENT_ID_HEADER = "X-Thermodepth-Event-Id"
RETRIED = (408, 429)
"""Answers below 500 that are retried (a timeout, too many requests)."""


def signature(body: bytes, secret: str) -> str:
    """``sha256=HEX``: the HMAC-SHA256 of ``body`` keyed with ``secret`` (UTF-8)."""
    return "sha256=" + hmac.new(secret.encode("utf-8"), body, hashlib.sha256).hexdigest()


class _NoRedirect(urllib.request.HTTPRedirectHandler):
    """A redirect is an answer, not followed (urllib would repeat a POST as a GET)."""

    def redirect_request(self, *args: Any, **kwargs: Any) -> None:
        return None


class WebhookOutput(Notifier):
    """A webhook target (module docstring)."""

    config: WebhookConfig

    def __init__(self, config: WebhookConfig, context: OutputContext) -> None:
        super().__init__(config, context)
        self.secret = first_line(config.secret_file, "webhook's secret")
        https = urllib.request.HTTPSHandler(context=self.ssl_context())
        self.opener = urllib.request.build_opener(https, _NoRedirect())

    def body(self, events: list[dict[str, Any]], digest: bool) -> tuple[bytes, str]:
        """A message's body and its id header."""
        if digest:
            ids = [str(e.get("id", "?")) for e in events]
            data: dict[str, Any] = {
                "digest": True,
                "count": len(events),
                "events": [self.public(e) for e in events],
            }
            event_id = f"digest-{ids[0]}-{ids[-1]}"
        else:
            data = self.public(events[0])
            event_id = str(events[0].get("id") or unstored_id(events[0]))
        return json.dumps(data).encode("utf-8"), event_id

    def report_body(self, path: Path, period: Period, summary: str) -> bytes:
        """A scheduled report's body: ``{"report": {...}}`` naming the file (where it is on
        the monitor's disk; its ``link`` when ``http.public_url`` is set)."""
        told: dict[str, Any] = {
            "file": path.name,
            "path": str(path),
            "from_utc": period.start_utc,
            "to_utc": period.end_utc,
            "period": period.label(),
            "summary": summary or None,
        }
        link = self.report_link(path)
        if link is not None:
            told["link"] = link
        return json.dumps({"report": told}).encode("utf-8")

    def send_report(self, path: Path, period: Period, summary: str) -> None:
        self.post(self.report_body(path, period, summary), f"report-{path.name}")

    def send(self, events: list[dict[str, Any]], digest: bool) -> None:
        self.post(*self.body(events, digest))

    def post(self, body: bytes, event_id: str) -> None:
        """POST a signed body (DeliveryError when it cannot be delivered)."""
        request = urllib.request.Request(
            self.config.url,
            data=body,
            method="POST",
            headers={
                "Content-Type": "application/json",
                "User-Agent": f"thermodepth/{__version__}",
                SIGNATURE_HEADER: signature(body, self.secret),
                EVENT_ID_HEADER: event_id,
            },
        )
        try:
            with self.opener.open(request, timeout=self.config.timeout_s) as answer:
                answer.read()
        except urllib.error.HTTPError as exc:
            exc.close()
            retry = exc.code >= 500 or exc.code in RETRIED
            raise DeliveryError(f"HTTP {exc.code} {exc.reason}", retry) from None
        except (urllib.error.URLError, OSError) as exc:
            why = exc.reason if isinstance(exc, urllib.error.URLError) else exc
            raise DeliveryError(f"cannot reach it ({why})", True) from None


def unstored_id(event: dict[str, Any]) -> str:
    """The id of an event the store could not take (it has none yet): its rig, rule, kind
    and time."""
    return f"unstored-{event.get('rig')}-{event.get('rule')}-{event['event']}-{event['time_utc']}"
