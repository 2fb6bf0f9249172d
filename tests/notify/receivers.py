"""Real receivers on this machine's loopback for the notification tests: an HTTP server that
records the JSON it is POSTed, an SMTP server (aiosmtpd) that records the mail, and the address
of a receiver that is down (a port nothing listens on)."""

from __future__ import annotations

import json
import socket
import threading
from contextlib import contextmanager
from email import message_from_bytes
from email.message import Message
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Iterator


@contextmanager
def http_receiver(port: int = 0, status: int = 200) -> Iterator[tuple[str, list[dict]]]:
    """(URL, the JSON bodies POSTed to it so far); on ``port`` (0: any free one), answering ``status``."""
    posts: list[dict] = []

    class Handler(BaseHTTPRequestHandler):
        def do_POST(self):  # noqa: N802 - http.server's name
            body = self.rfile.read(int(self.headers["Content-Length"]))
            posts.append(json.loads(body) | {"_content_type": self.headers["Content-Type"]})
            self.send_response(status)
            self.end_headers()
            self.wfile.write(b"ok")

        def log_message(self, *args):  # quiet
            pass

    server = ThreadingHTTPServer(("127.0.0.1", port), Handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}/hook", posts
    finally:
        server.shutdown()
        server.server_close()


def free_port() -> int:
    """A loopback port nothing listens on (a receiver that is down)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextmanager
def smtp_receiver(port: int = 0, logins: list[tuple[str, str]] | None = None) -> Iterator[tuple[int, list[Message]]]:
    """(port, the mails received so far, parsed); on ``port`` (0: any free one). With ``logins``
    a list, the server offers AUTH without TLS and records each (user, password) there."""
    from aiosmtpd.controller import Controller
    from aiosmtpd.smtp import AuthResult

    mails: list[Message] = []

    def authenticator(server, session, envelope, mechanism, auth_data):
        logins.append((auth_data.login.decode(), auth_data.password.decode()))
        return AuthResult(success=True)

    class Handler:
        async def handle_DATA(self, server, session, envelope):  # noqa: N802 - aiosmtpd's name
            mails.append(message_from_bytes(envelope.content))
            return "250 Message accepted"

    auth = {} if logins is None else {"authenticator": authenticator, "auth_require_tls": False}
    controller = Controller(Handler(), hostname="127.0.0.1", port=port or free_port(), **auth)
    controller.start()
    try:
        yield controller.port, mails
    finally:
        controller.stop()
