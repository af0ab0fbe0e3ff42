"""The monitor's notifications (``notify:``) to real receivers over loopback: a webhook
receiver (the standard library's HTTP server) checking each signature as the docs' receiver
does, and an SMTP server (aiosmtpd) with STARTTLS on a certificate made here and AUTH. Nothing
lost while the receiver is away or answers 503 (each event id received, at least once), across
a restart of the monitor; a 4xx or SMTP 5xx not retried and counted; the hourly limit holding
events back and a digest of them following. The retries' backoff and the limit's hour are
made short by setting :mod:`thermodepth.monitor.outputs.notify`'s constants."""

from __future__ import annotations

import hashlib
import hmac
import json
import socket
import threading
from collections import Counter
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any

import pytest

from monitor_helpers import monitor_config, settings_file, wait_for
from thermodepth.errors import InputError
from thermodepth.monitor import Monitor, load_config
from thermodepth.monitor.outputs import describe_outputs
from thermodepth.monitor.outputs import notify as notify_module
from thermodepth.monitor.store import EventStore

SECRET = "s3cret-for-the-hook"
PUBLIC = "https://monitor.example/thermo"


@pytest.fixture(autouse=True)
def short_waits(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(notify_module, "BACKOFF_S", (0.05, 0.1, 0.2))


def verified(body: bytes, header: str | None, secret: str = SECRET) -> bool:
    """The receiver's check, as docs/monitor.md shows it."""
    expected = "sha256=" + hmac.new(secret.encode(), body, hashlib.sha256).hexdigest()
    return header is not None and hmac.compare_digest(expected, header)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Receiver:
    """A webhook receiver on ``port``: answers ``status`` (204, 503, 400 ...), keeps every
    request (its id header, body, whether its signature checks)."""

    def __init__(self, port: int = 0, status: int = 204) -> None:
        self.status = status
        self.got: list[dict[str, Any]] = []
        self._lock = threading.Lock()
        outer = self

        class Handler(BaseHTTPRequestHandler):
            def do_POST(self) -> None:
                body = self.rfile.read(int(self.headers["Content-Length"]))
                with outer._lock:
                    outer.got.append({
                        "id": self.headers["X-Thermodepth-Event-Id"],
                        "signature": self.headers["X-Thermodepth-Signature"],
                        "body": body,
                        "ok": verified(body, self.headers["X-Thermodepth-Signature"]),
                        "answered": outer.status,
                    })  # fmt: skip
                self.send_response(outer.status)
                self.send_header("Content-Length", "0")
                self.end_headers()

            def log_message(self, *args: Any) -> None:
                pass

        self.server = ThreadingHTTPServer(("127.0.0.1", port), Handler)
        self.port = self.server.server_address[1]
        threading.Thread(target=self.server.serve_forever, daemon=True).start()

    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}/hook/abc123token"

    def requests(self) -> list[dict[str, Any]]:
        with self._lock:
            return list(self.got)

    def accepted(self) -> list[dict[str, Any]]:
        """The bodies of the requests answered 2xx, as JSON."""
        return [json.loads(r["body"]) for r in self.requests() if r["answered"] < 300]

    def close(self) -> None:
        self.server.shutdown()
        self.server.server_close()


def accepted_ids(receiver: Receiver) -> set[int]:
    ids = set()
    for body in receiver.accepted():
        ids |= {e["id"] for e in body["events"]} if body.get("digest") else {body["id"]}
    return ids


def webhook_monitor(folder: Path, url: str, **target: Any) -> tuple[Monitor, str]:
    """A monitor of one simulated rig (``hot`` flapping) with one webhook target; started."""
    settings = settings_file(folder)
    (folder / "hook.key").write_text(SECRET + "\n", encoding="utf-8")
    entry = {"kind": "webhook", "name": "ops", "url": url, "secret_file": "hook.key",
             "events": ["alarm"], "max_per_hour": 100_000, "timeout_s": 5, **target}  # fmt: skip
    path = monitor_config(
        folder,
        [{"name": "a", "source": "sim", "settings": settings.name}],
        http={"listen": None, "public_url": PUBLIC},
        notify=[entry],
    )
    monitor = Monitor(load_config(path))
    monitor.start()
    return monitor, "webhook:ops"


def test_a_receiver_away_then_back_gets_every_event_signed(tmp_path: Path) -> None:
    receiver = Receiver(status=503)
    monitor, name = webhook_monitor(tmp_path, receiver.url())
    try:
        wait_for(lambda: len(receiver.requests()) >= 3 and monitor.store.waiting(name) >= 5)
        during = {e["id"] for e in monitor.store.outbox(100_000, target=name)}
        receiver.status = 204  # back
        wait_for(lambda: during <= accepted_ids(receiver))
        status = monitor.status()["outputs"][name]
    finally:
        monitor.stop()
        receiver.close()
    got = receiver.requests()
    assert all(r["ok"] for r in got)  # every request signed with the secret
    assert status["retries"] >= 3 and status["failed"] == 0 and status["delivered"] >= len(during)
    assert status["target"] == f"http://127.0.0.1:{receiver.port}/..."  # no token shown
    store = EventStore(tmp_path / "store" / "events.sqlite")
    stored = {e["id"]: e for e in store.events(100_000)}
    bodies = receiver.accepted()
    for body in bodies:
        assert body["event"] == "alarm"  # the target's filter: alarms only, no clears
        assert body["rule"] == stored[body["id"]]["rule"] and body["rig"] == "a"
        links = body["links"]
        assert links["event"] == f"{PUBLIC}/api/events/{body['id']}"
        assert {f"{links['event']}/{name}" for name in body["evidence"]} <= set(links.values())
    assert {r["id"] for r in got if r["answered"] < 300} == {str(b["id"]) for b in bodies}
    # what was not yet delivered at the stop is still waiting on disk: nothing lost
    alarms = {i for i, e in stored.items() if e["event"] == "alarm"}
    assert alarms == accepted_ids(receiver) | {e["id"] for e in store.outbox(100_000, target=name)}
    # the check a receiver makes detects a body changed, or another secret
    one = next(r for r in got if r["answered"] < 300)
    changed = one["body"].replace(b'"alarm"', b'"clear"', 1)
    assert changed != one["body"] and not verified(changed, one["signature"])
    assert not verified(one["body"], one["signature"], secret="another secret")


def test_a_refused_event_is_not_retried_and_is_counted(tmp_path: Path) -> None:
    receiver = Receiver(status=400)
    monitor, name = webhook_monitor(tmp_path, receiver.url())
    output = monitor.output(name)
    try:
        wait_for(lambda: monitor.status()["outputs"][name]["failed"] >= 5)
    finally:
        monitor.stop()
        receiver.close()
    tries = Counter(r["id"] for r in receiver.requests())
    assert tries and set(tries.values()) == {1}  # each once: never again
    status = vars(output)
    assert status["retries"] == 0 and status["last_error"] == "HTTP 400 Bad Request"
    assert status["failed"] == len(tries) and status["delivered"] == 0
    store = EventStore(tmp_path / "store" / "events.sqlite")
    waiting = {str(e["id"]) for e in store.outbox(100_000, target=name)}
    assert not waiting & set(tries)  # refused for good: out of the outbox


def test_undelivered_events_go_after_a_restart(tmp_path: Path) -> None:
    port = free_port()
    url = f"http://127.0.0.1:{port}/hook"
    with socket.socket() as taken:  # bound, not listening: every connection refused
        taken.bind(("127.0.0.1", port))
        first, name = webhook_monitor(tmp_path, url)
        try:
            wait_for(lambda: first.store.waiting(name) >= 5)
            wait_for(lambda: first.status()["outputs"][name]["retries"] >= 2)
            assert "cannot reach it" in first.status()["outputs"][name]["last_error"]
        finally:
            first.stop()
    store = EventStore(tmp_path / "store" / "events.sqlite")
    queued = {e["id"] for e in store.outbox(100_000, target=name)}
    store.close()
    assert len(queued) >= 5
    receiver = Receiver(port)
    again, _ = webhook_monitor(tmp_path, url)
    try:
        wait_for(lambda: queued <= accepted_ids(receiver))
    finally:
        again.stop()
        receiver.close()
    assert all(r["ok"] for r in receiver.requests())


def test_beyond_max_per_hour_events_are_held_back_then_a_digest(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(notify_module, "HOUR_S", 2.0)
    receiver = Receiver()
    monitor, name = webhook_monitor(tmp_path, receiver.url(), max_per_hour=2)
    try:
        wait_for(lambda: any(b.get("digest") for b in receiver.accepted()))
        wait_for(lambda: monitor.status()["outputs"][name]["digests"] >= 2)
    finally:
        monitor.stop()
        receiver.close()
    bodies = receiver.accepted()
    digests = [b for b in bodies if b.get("digest")]
    assert all(d["count"] == len(d["events"]) >= 2 for d in digests)
    assert all(e["event"] == "alarm" and "links" in e for d in digests for e in d["events"])
    ids = [b["id"] for b in bodies if not b.get("digest")]
    ids += [e["id"] for d in digests for e in d["events"]]
    assert len(ids) == len(set(ids))  # each event in one message
    assert len(bodies) < len(ids)  # fewer messages than events: the digests held them
    heads = [r["id"] for r in receiver.requests() if r["id"].startswith("digest-")]
    assert heads == [f"digest-{d['events'][0]['id']}-{d['events'][-1]['id']}" for d in digests]
    store = EventStore(tmp_path / "store" / "events.sqlite")
    alarms = {e["id"] for e in store.events(100_000) if e["event"] == "alarm"}
    assert alarms == set(ids) | {e["id"] for e in store.outbox(100_000, target=name)}


def test_check_describes_each_target_without_secrets(tmp_path: Path) -> None:
    settings = settings_file(tmp_path)
    (tmp_path / "hook.key").write_text(SECRET, encoding="utf-8")
    (tmp_path / "smtp.pw").write_text("mail-password", encoding="utf-8")
    path = monitor_config(
        tmp_path,
        [{"name": "a", "source": "sim", "settings": settings.name}],
        notify=[
            {
                "kind": "webhook",
                "url": "https://hooks.example/T0/B0/tokenXYZ?key=abc",
                "secret_file": "hook.key",
                "events": ["alarm", "escalated", "sensor_fault"],
            },
            {
                "kind": "email",
                "smtp": "mail.example:587",
                "user": "monitor",
                "password_file": "smtp.pw",
                "from": "monitor@plant.example",
                "to": ["ops@plant.example", "lead@plant.example"],
                "events": ["hot"],
                "max_per_hour": 10,
            },
        ],
    )
    lines = describe_outputs(load_config(path))
    assert lines == [
        "webhook webhook:hooks.example: POST to https://hooks.example/..., signed; events "
        "alarm, escalated, sensor_fault; at most 60/h, then a digest",
        "e-mail email:ops@plant.example: from monitor@plant.example to ops@plant.example, "
        "lead@plant.example via mail.example:587 (STARTTLS, as monitor); events hot; at most "
        "10/h, then a digest",
    ]
    assert not any(s in " ".join(lines) for s in (SECRET, "mail-password", "tokenXYZ", "abc"))


def test_config_problems_are_one_line_each(tmp_path: Path) -> None:
    settings = settings_file(tmp_path)
    (tmp_path / "empty.key").write_text("", encoding="utf-8")
    path = monitor_config(
        tmp_path,
        [{"name": "a", "source": "sim", "settings": settings.name}],
        http={"public_url": "monitor.example"},
        notify=[
            {
                "kind": "webhook",
                "url": "ftp://x",
                "secret_file": "empty.key",
                "events": ["alarm", "hto"],
            },
            {"kind": "webhook", "url": "https://x/2", "secret_file": "missing.key"},
            {
                "kind": "email",
                "smtp": "mail:smtp",
                "user": "u",
                "from": "me",
                "to": ["ops@x"],
                "starttls": False,
            },
        ],
    )
    with pytest.raises(InputError) as caught:
        load_config(path)
    lines = str(caught.value).splitlines()
    p = path
    assert lines == [
        f"{p}: http.public_url: 'monitor.example': expected http(s)://HOST[:PORT][/PATH]",
        f"{p}: notify: 'webhook:x' twice: give each target its own name",
        f"{p}: notify.0 (webhook:x).events: 'hto': neither an event (alarm, escalated, "
        "acknowledged, clear) nor a rule (hot, latched, sensor_fault, storage_fault)",
        f"{p}: notify.0 (webhook:x).url: 'ftp://x': expected https://HOST[:PORT]/PATH",
        f"{p}: notify.0 (webhook:x).secret_file: {tmp_path / 'empty.key'}: empty (the first "
        "line is the webhook's secret)",
        f"{p}: notify.1 (webhook:x).secret_file: {tmp_path / 'missing.key'}: cannot read the "
        "webhook's secret (No such file or directory)",
        f"{p}: notify.2 (email:ops@x).smtp: 'mail:smtp': expected HOST[:PORT] (mail.example:587)",
        f"{p}: notify.2 (email:ops@x): 'me': not an e-mail address",
        f"{p}: notify.2 (email:ops@x): user and password_file go together",
        f"{p}: notify.2 (email:ops@x): a password is only sent over TLS: set starttls: true",
    ]
    path.write_text(path.read_text().replace("kind: email", "kind: sms"), encoding="utf-8")
    with pytest.raises(InputError, match=r"notify\.2: Input tag 'sms' found using 'kind'"):
        load_config(path)


# -- e-mail ---------------------------------------------------------------------------------------


def certificate(folder: Path) -> tuple[Path, Path, Path]:
    """A CA and a certificate it signed for 127.0.0.1: (ca.pem, cert.pem, key.pem)."""
    x509 = pytest.importorskip(
        "cryptography.x509", reason="the test certificate needs cryptography"
    )
    import datetime
    import ipaddress

    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

    now = datetime.datetime.now(datetime.timezone.utc)
    ca_key, key = ec.generate_private_key(ec.SECP256R1()), ec.generate_private_key(ec.SECP256R1())
    ca_name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "thermodepth test CA")])
    ca_ski = x509.SubjectKeyIdentifier.from_public_key(ca_key.public_key())
    ca = (
        x509.CertificateBuilder().subject_name(ca_name).issuer_name(ca_name)
        .public_key(ca_key.public_key()).serial_number(x509.random_serial_number())
        .not_valid_before(now - datetime.timedelta(minutes=5))
        .not_valid_after(now + datetime.timedelta(days=1))
        .add_extension(x509.BasicConstraints(ca=True, path_length=None), critical=True)
        .add_extension(x509.KeyUsage(False, False, False, False, False, True, True, False, False),
                       critical=True)
        .add_extension(ca_ski, critical=False)
        .sign(ca_key, hashes.SHA256())
    )  # fmt: skip
    leaf = (
        x509.CertificateBuilder()
        .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "127.0.0.1")]))
        .issuer_name(ca_name).public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - datetime.timedelta(minutes=5))
        .not_valid_after(now + datetime.timedelta(days=1))
        .add_extension(x509.SubjectAlternativeName(
            [x509.IPAddress(ipaddress.ip_address("127.0.0.1")), x509.DNSName("localhost")]),
            critical=False)
        .add_extension(x509.ExtendedKeyUsage([ExtendedKeyUsageOID.SERVER_AUTH]), critical=False)
        .add_extension(x509.AuthorityKeyIdentifier.from_issuer_subject_key_identifier(ca_ski),
                       critical=False)
        .sign(ca_key, hashes.SHA256())
    )  # fmt: skip
    paths = folder / "ca.pem", folder / "cert.pem", folder / "key.pem"
    paths[0].write_bytes(ca.public_bytes(serialization.Encoding.PEM))
    paths[1].write_bytes(leaf.public_bytes(serialization.Encoding.PEM))
    paths[2].write_bytes(
        key.private_bytes(
            serialization.Encoding.PEM,
            serialization.PrivateFormat.PKCS8,
            serialization.NoEncryption(),
        )
    )
    return paths


class Mailbox:
    """aiosmtpd's handler: refuses ``nobody@`` for good (550), answers the first
    ``temporary`` messages 451 (try later), keeps the rest."""

    def __init__(self, temporary: int) -> None:
        self.temporary = temporary
        self.messages: list[Any] = []
        self.refused = 0
        self.tls: list[bool] = []

    async def handle_RCPT(  # noqa: N802 (aiosmtpd's name)
        self, server: Any, session: Any, envelope: Any, address: str, options: Any
    ) -> str:
        if address.startswith("nobody@"):
            return "550 5.1.1 no such user"
        envelope.rcpt_tos.append(address)
        return "250 OK"

    async def handle_DATA(self, server: Any, session: Any, envelope: Any) -> str:  # noqa: N802
        import email
        import email.policy

        self.tls.append(session.ssl is not None)
        if self.temporary > 0:
            self.temporary -= 1
            self.refused += 1
            return "451 4.3.0 try again later"
        self.messages.append(
            email.message_from_bytes(envelope.content, policy=email.policy.default)
        )
        return "250 OK"


def test_email_over_starttls_with_its_overlay_and_smtp_failures(tmp_path: Path) -> None:
    pytest.importorskip("aiosmtpd", reason="the e-mail tests' SMTP server is aiosmtpd")
    import ssl

    from aiosmtpd.controller import Controller
    from aiosmtpd.smtp import AuthResult, LoginPassword

    _, cert, key = certificate(tmp_path)  # the CA: the config's ca_file
    tls = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH)
    tls.load_cert_chain(cert, key)
    logins: list[tuple[str, bool]] = []

    def authenticator(server: Any, session: Any, envelope: Any, mechanism: str,
                      data: Any) -> AuthResult:  # fmt: skip
        ok = isinstance(data, LoginPassword) and (data.login, data.password) == (
            b"monitor", b"mail-password")  # fmt: skip
        logins.append((mechanism, ok))
        return AuthResult(success=ok)

    box = Mailbox(temporary=3)
    port = free_port()
    smtp = Controller(box, hostname="127.0.0.1", port=port, tls_context=tls,
                      require_starttls=True, authenticator=authenticator,
                      auth_require_tls=True)  # fmt: skip
    smtp.start()
    settings = settings_file(tmp_path)
    (tmp_path / "smtp.pw").write_text("mail-password\n", encoding="utf-8")
    common = {"kind": "email", "smtp": f"127.0.0.1:{port}", "starttls": True, "user": "monitor",
              "password_file": "smtp.pw", "ca_file": "ca.pem", "from": "monitor@plant.example",
              "events": ["alarm"], "timeout_s": 10}  # fmt: skip
    path = monitor_config(
        tmp_path,
        [{"name": "a", "source": "sim", "settings": settings.name, "location": "press 7"}],
        http={"listen": None, "public_url": PUBLIC},
        notify=[
            {**common, "name": "ops", "to": ["ops@plant.example"]},
            {**common, "name": "bounce", "to": ["nobody@plant.example"]},
        ],
    )
    monitor = Monitor(load_config(path))
    monitor.start()
    try:

        def pictured() -> list[Any]:
            return [m for m in box.messages if any(True for _ in m.iter_attachments())]

        wait_for(lambda: len(pictured()) >= 2)
        wait_for(lambda: monitor.status()["outputs"]["email:bounce"]["failed"] >= 2)
        ops = monitor.status()["outputs"]["email:ops"]
        bounce = monitor.status()["outputs"]["email:bounce"]
    finally:
        monitor.stop()
        smtp.stop()
    assert box.refused == 3 and ops["retries"] >= 3 and ops["failed"] == 0
    assert bounce["retries"] == 0 and "SMTP refused every recipient ([550])" in bounce["last_error"]
    assert all(box.tls) and logins and all(ok for _, ok in logins)  # STARTTLS, then AUTH
    store = EventStore(tmp_path / "store" / "events.sqlite")
    stored = {e["id"]: e for e in store.events(100_000)}
    for m in box.messages:
        assert m["To"] == "ops@plant.example"
        event = stored[int(m["X-Thermodepth-Event-Id"])]
        value = f" {event['value_c']} C" if event["value_c"] is not None else ""
        assert m["Subject"] == f"[thermodepth] a: ALARM {event['rule']} [alarm]{value}"
        text = m.get_body(("plain",)).get_content()
        assert text.startswith("a at press 7: ALARM") and f"{PUBLIC}/api/events/" in text
    for m in pictured():
        (png,) = list(m.iter_attachments())
        assert png.get_content_type() == "image/png"
        assert png.get_content().startswith(b"\x89PNG\r\n\x1a\n")
