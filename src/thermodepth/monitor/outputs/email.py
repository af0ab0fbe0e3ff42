"""An e-mail notification target (``notify: [{kind: email, ...}]``): each event a message,
delivered from the outbox (:mod:`.notify`) over the standard library's smtplib.

Subject ``[thermodepth] RIG: ALARM hot [alarm] 61.2 C`` (rig, what happened, rule, level,
value); the body the event's line, where and when, its fields, and links to it and its
evidence when ``http.public_url`` is set; the event's overlay (``snapshot.png``, drawn just
after the event) attached when it has one. A digest lists the events held back by the hourly
limit, one line each. ``X-Thermodepth-Event-Id`` carries the event's id (at least once: a
repeat has the same). A scheduled inspection report (:mod:`..reports`) is a message of its
own with the file attached (``X-Thermodepth-Report``: its name).

With ``starttls`` the connection is upgraded before anything else is said (the server's
certificate verified, against ``ca_file`` when given), and only then does it log in. A 4xx
answer, a refused, dropped or timed-out connection is retried; a 5xx (the message, a recipient
or the login refused) is not.
"""

from __future__ import annotations

import smtplib
from email.message import EmailMessage
from email.utils import formatdate, make_msgid
from pathlib import Path
from typing import Any

from ...alarms import event_line
from ...app.report import Period
from ..config import EmailConfig, first_line
from .base import OutputContext
from .notify import DeliveryError, Notifier, label


class EmailOutput(Notifier):
    """An e-mail target (module docstring)."""

    config: EmailConfig

    def __init__(self, config: EmailConfig, context: OutputContext) -> None:
        super().__init__(config, context)
        self.host, self.port = config.address()
        self.password = (
            None
            if config.password_file is None
            else first_line(config.password_file, "SMTP password")
        )

    def message(self, events: list[dict[str, Any]], digest: bool) -> EmailMessage:
        """The message of one event, or of a digest."""
        msg = EmailMessage()
        msg["From"], msg["To"] = self.config.sender, ", ".join(self.config.to)
        msg["Date"], msg["Message-ID"] = formatdate(localtime=False), make_msgid("thermodepth")
        if digest:
            rigs = sorted({str(e.get("rig")) for e in events})
            msg["Subject"] = f"[thermodepth] {len(events)} events held back ({', '.join(rigs)})"
            ids = [str(e.get("id", "?")) for e in events]
            msg["X-Thermodepth-Event-Id"] = f"digest-{ids[0]}-{ids[-1]}"
            lines = [
                f"{len(events)} events went beyond {self.config.max_per_hour} messages an "
                "hour and were held back:",
                "",
                *(f"{e.get('time_utc')}  {e.get('rig')}: {event_line(e)}" for e in events),
            ]
            if self.public_url is not None:
                lines += ["", f"Every event: {self.public_url}/events"]
            msg.set_content("\n".join(lines) + "\n")
            return msg
        event = events[0]
        value = "" if event.get("value_c") is None else f" {event['value_c']} C"
        msg["Subject"] = (
            f"[thermodepth] {event.get('rig')}: {str(event.get('event')).upper()} "
            f"{event.get('rule')} [{event.get('level')}]{value}"
        )
        msg["X-Thermodepth-Event-Id"] = str(event.get("id", "unstored"))
        told = self.public(event)
        where = f" at {event['location']}" if event.get("location") else ""
        lines = [f"{event.get('rig')}{where}: {event_line(event)}", f"at {event.get('time_utc')}"]
        lines += ["", *(f"{k}: {v}" for k, v in told.items() if k not in ("links", "evidence"))]
        if "links" in told:
            lines += ["", *(f"{k}: {v}" for k, v in told["links"].items())]
        msg.set_content("\n".join(lines) + "\n")
        picture = self.snapshot(event)
        if picture is not None:
            try:
                data = picture.read_bytes()
            except OSError:
                data = b""  # deleted since by the storage rule: the message goes without
            if data:
                name = f"{event.get('rig')}-{event.get('rule')}-{event.get('id')}.png"
                msg.add_attachment(data, maintype="image", subtype="png", filename=name)
        return msg

    def report_message(self, path: Path, period: Period, summary: str) -> EmailMessage:
        """A scheduled report's message: the file attached."""
        msg = EmailMessage()
        msg["From"], msg["To"] = self.config.sender, ", ".join(self.config.to)
        msg["Date"], msg["Message-ID"] = formatdate(localtime=False), make_msgid("thermodepth")
        msg["Subject"] = f"[thermodepth] inspection report {period.label()}"
        msg["X-Thermodepth-Report"] = path.name
        held = f" ({summary})" if summary else ""
        lines = [f"The monitor's inspection report of {period.label()}{held} is attached: "
                 f"{path.name}."]  # fmt: skip
        link = self.report_link(path)
        if link is not None:
            lines += ["", f"It is also at {link}"]
        msg.set_content("\n".join(lines) + "\n")
        kind = ("application", "pdf") if path.suffix == ".pdf" else ("text", "html")
        try:
            data = path.read_bytes()
        except OSError as exc:
            raise DeliveryError(f"{path}: cannot read it ({exc.strerror or exc})", True) from None
        msg.add_attachment(data, maintype=kind[0], subtype=kind[1], filename=path.name)
        return msg

    def send_report(self, path: Path, period: Period, summary: str) -> None:
        self.deliver(self.report_message(path, period, summary), path.name)

    def send(self, events: list[dict[str, Any]], digest: bool) -> None:
        self.deliver(self.message(events, digest), ", ".join(map(label, events)))

    def deliver(self, msg: EmailMessage, what: str) -> None:
        """Send a message (``what``: it in a few words, for the log)."""
        # before MAIL FROM a refusal is the target's (a login, TLS), not the message's
        sending = False
        try:
            with smtplib.SMTP(self.host, self.port, timeout=self.config.timeout_s) as smtp:
                if self.config.starttls:
                    smtp.starttls(context=self.ssl_context())
                if self.config.user is not None and self.password is not None:
                    smtp.login(self.config.user, self.password)
                sending = True
                refused = smtp.send_message(msg)
        except smtplib.SMTPRecipientsRefused as exc:
            codes = [code for code, _ in exc.recipients.values()]
            why = f"SMTP refused every recipient ({codes})"
            raise DeliveryError(why, min(codes) < 500) from None
        except smtplib.SMTPResponseException as exc:
            said = exc.smtp_error
            text = said.decode("utf-8", "replace") if isinstance(said, bytes) else str(said)
            # a wrong password or a server that refuses us is retried (and shown), never a
            # reason to drop every event waiting: only the message's own refusal is final
            final = sending and exc.smtp_code >= 500
            raise DeliveryError(f"SMTP {exc.smtp_code} {text}", not final) from None
        except smtplib.SMTPNotSupportedError as exc:
            raise DeliveryError(f"SMTP: {exc}", True) from None
        except (smtplib.SMTPException, OSError) as exc:
            raise DeliveryError(f"SMTP {self.host}:{self.port}: {exc}", True) from None
        if refused:
            self.log.warning("%s: %s not delivered to %s", self.name, what, refused)
