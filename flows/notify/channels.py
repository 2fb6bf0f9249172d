"""Sending one message on one channel, with retries: a webhook's JSON POST (httpx, which
Prefect brings) and mail (the standard library's ``smtplib`` and ``email``). Nothing here raises
for a failed send: :func:`deliver` returns what happened, the caller records it."""

from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass
from urllib.parse import urlsplit

from schemas.plant_config import MailSpec, NotifySpec

RETRY_WAITS_S: tuple[float, ...] = (2.0, 10.0, 30.0)
"""Waits before the 2nd, 3rd, 4th … attempt of one run (the last repeats). [s]"""
CHANNELS: tuple[str, ...] = ("webhook", "mail")


@dataclass(frozen=True)
class Outcome:
    """How one message went on one channel in this run."""

    ok: bool
    attempts: int
    error: str = ""


def channels(spec: NotifySpec) -> list[tuple[str, str]]:
    """The configured channels and their targets as recorded (the webhook's host, the mail's
    recipients: nothing secret)."""
    out = []
    if spec.webhook_url:
        out.append(("webhook", urlsplit(spec.webhook_url).netloc))
    if spec.mail is not None:
        out.append(("mail", ", ".join(spec.mail.to)))
    return out


def post_webhook(url: str, payload: dict, timeout_s: float) -> None:
    """POST ``payload`` as JSON; an HTTP status of 400 or more raises."""
    import httpx

    r = httpx.post(url, content=json.dumps(payload).encode(), headers={"Content-Type": "application/json"}, timeout=timeout_s)
    r.raise_for_status()


def send_mail(mail: MailSpec, subject: str, body: str, timeout_s: float) -> None:
    """One plain-text mail through the relay (STARTTLS and login as configured)."""
    import smtplib
    import ssl
    from email.message import EmailMessage
    from email.utils import formatdate, make_msgid

    password = None
    if mail.password_env is not None:
        password = os.environ.get(mail.password_env)
        if not password:
            raise RuntimeError(f"environment variable {mail.password_env} (notify.mail.password_env) is not set")
    msg = EmailMessage()
    msg["Subject"], msg["From"], msg["To"] = subject, mail.sender, ", ".join(mail.to)
    msg["Date"], msg["Message-ID"] = formatdate(localtime=False), make_msgid(domain=mail.sender.split("@")[1])
    msg.set_content(body)
    with smtplib.SMTP(mail.host, mail.port, timeout=timeout_s) as smtp:
        if mail.starttls:
            smtp.starttls(context=ssl.create_default_context())
        if password is not None:
            smtp.login(mail.user or mail.sender, password)
        smtp.send_message(msg)


def deliver(spec: NotifySpec, channel: str, subject: str, body: str, payload: dict) -> Outcome:
    """Send on ``channel`` with up to ``spec.retries`` attempts, waiting :data:`RETRY_WAITS_S`
    between them; never raises."""
    if (channel == "webhook" and not spec.webhook_url) or (channel == "mail" and spec.mail is None):
        return Outcome(False, 0, f"no {channel} is configured in [notify] now")
    error = ""
    for attempt in range(1, spec.retries + 1):
        if attempt > 1:
            time.sleep(RETRY_WAITS_S[min(attempt - 2, len(RETRY_WAITS_S) - 1)])
        try:
            if channel == "webhook":
                post_webhook(spec.webhook_url, payload, spec.timeout_s)
            else:
                send_mail(spec.mail, subject, body, spec.timeout_s)
            return Outcome(True, attempt)
        except Exception as exc:  # noqa: BLE001 - any failure of a send is recorded, never raised
            error = f"{type(exc).__name__}: {str(exc).strip().splitlines()[0] if str(exc).strip() else ''}".rstrip(": ")
    return Outcome(False, spec.retries, error)


def test_message(config) -> list[tuple[str, str, Outcome]]:
    """``valvemon notify --test``: a test message on every configured channel of ``config``
    (a :class:`schemas.plant_config.PlantConfig` with ``[notify]``): (channel, target, outcome)."""
    from datetime import datetime, timezone

    now = datetime.now(timezone.utc)
    subject = f"valvemon {config.name}: test message"
    body = f"valvemon, plant {config.name}: a test message sent {now:%Y-%m-%d %H:%M} UTC by valvemon notify --test. [notify] reaches you."
    payload = {"text": body, "plant": config.name, "run_at": now.isoformat(), "report": "", "changes": [], "test": True}
    return [(ch, target, deliver(config.notify, ch, subject, body, payload)) for ch, target in channels(config.notify)]
