"""The door of the 3D monitors: viser listens on a private loopback port, this gate on the public one.

Every TCP connection to a monitor starts with an HTTP request (the page, its assets, the viser
WebSocket handshake). The gate reads that request head and lets the connection through (bytes
spliced both ways to viser) only for a valid API token of at least ``viewer``: ``?token=`` on the
page URL (answered with a redirect that stores it in an HttpOnly, SameSite=Strict cookie, which the
browser then sends with the assets and the WebSocket handshake) or that cookie. Revoking the token
closes its open monitor connections at once (Authenticator.watch). With auth off every caller passes.

The gate listens from the server's start: until its monitor is ready (:meth:`MonitorGate.attach`) an
authorised page request gets a small page that says what the monitor waits for, with a progress bar, and
reloads itself every STARTING_REFRESH_S, turning into the monitor once it is up (never a refused connection
or a broken frame); a refused request gets a page saying how to open the monitor with a token.
"""

from __future__ import annotations

import asyncio
import contextlib
import html
import threading
import time
from collections.abc import Callable, Sequence
from http.cookies import SimpleCookie
from urllib.parse import parse_qsl, urlencode, urlsplit

from backend.core.auth import Authenticator, Principal, Role

__all__ = ["COOKIE", "MonitorGate"]

COOKIE = "acs_twin_monitor"
HEAD_LIMIT = 16_384  # an HTTP request head longer than this is refused
HEAD_TIMEOUT_S = 10.0
SPLICE_BYTES = 1 << 16
STARTING_REFRESH_S = 2


def _page(status: str, title: str, body: str, refresh_s: int | None = None) -> bytes:
    """A small self-contained HTML answer (dark, like the monitors), optionally reloading itself."""
    refresh = f'<meta http-equiv="refresh" content="{refresh_s}">' if refresh_s else ""
    text = (
        f'<!doctype html><html><head><meta charset="utf-8">{refresh}<title>{html.escape(title)}</title>'
        "<style>body{background:#1a1b1e;color:#c1c2c5;font:16px system-ui,sans-serif;display:flex;"
        "align-items:center;justify-content:center;height:100vh;margin:0}progress{width:20rem}</style></head>"
        f"<body><main><h1>{html.escape(title)}</h1>{body}</main></body></html>"
    ).encode()
    head = [
        f"HTTP/1.1 {status}",
        "Content-Type: text/html; charset=utf-8",
        f"Content-Length: {len(text)}",
        "Cache-Control: no-store",
        "Connection: close",
    ]
    return ("\r\n".join(head) + "\r\n\r\n").encode() + text


def _answer(status: str, headers: dict[str, str] | None = None) -> bytes:
    lines = [
        f"HTTP/1.1 {status}",
        "Content-Length: 0",
        "Connection: close",
        *(f"{k}: {v}" for k, v in (headers or {}).items()),
    ]
    return ("\r\n".join(lines) + "\r\n\r\n").encode()


def _token_of(head: bytes) -> tuple[str | None, str | None]:
    """(token from ?token=, token from the cookie) of a request head."""
    lines = head.decode("latin-1").split("\r\n")
    target = lines[0].split(" ")[1] if len(lines[0].split(" ")) >= 2 else "/"
    query = dict(parse_qsl(urlsplit(target).query))
    cookie = None
    for line in lines[1:]:
        name, _, value = line.partition(":")
        if name.strip().lower() == "cookie":
            jar = SimpleCookie()
            with contextlib.suppress(Exception):
                jar.load(value.strip())
            if COOKIE in jar:
                cookie = jar[COOKIE].value
    return query.get("token"), cookie


def _without_token(head: bytes) -> str:
    target = urlsplit(head.decode("latin-1").split("\r\n")[0].split(" ")[1])
    query = urlencode([(k, v) for k, v in parse_qsl(target.query) if k != "token"])
    return target.path + (f"?{query}" if query else "")


class MonitorGate:
    """A token-checking TCP front for one viser server, running its own event loop in a daemon thread."""

    def __init__(
        self,
        auth: Authenticator,
        host: str,
        public_port: int,
        private_port: int | None,
        role: str = "3D",
        progress: Callable[[], str] = lambda: "starting",
    ) -> None:
        self._auth, self._host, self._public, self._private = auth, host, public_port, private_port
        self._role, self._progress, self._started = role, progress, time.monotonic()
        self._loop = asyncio.new_event_loop()
        self._server: asyncio.Server | None = None
        self._ready = threading.Event()
        self.port = public_port
        self.refused = 0

    def attach(self, private_port: int) -> None:
        """The monitor is up on this loopback port: splice authorised connections to it from now on."""
        self._private = private_port

    def start(self) -> int:
        """Listen on the public port (0: any); returns the bound port."""
        threading.Thread(target=self._loop.run_forever, name=f"monitor-gate-{self._public}", daemon=True).start()
        future = asyncio.run_coroutine_threadsafe(
            asyncio.start_server(self._handle, self._host, self._public), self._loop
        )
        self._server = future.result(30)
        self.port = int(self._server.sockets[0].getsockname()[1])
        return self.port

    def stop(self) -> None:
        """Stop listening, drop open connections (their tasks cancelled and awaited), then stop the loop."""

        async def shutdown() -> None:
            if self._server is not None:
                self._server.close()
            tasks = [t for t in asyncio.all_tasks() if t is not asyncio.current_task()]
            for task in tasks:
                task.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)

        if self._loop.is_running():
            with contextlib.suppress(Exception):  # a loop that cannot finish in time is stopped all the same
                asyncio.run_coroutine_threadsafe(shutdown(), self._loop).result(5.0)
        self._loop.call_soon_threadsafe(self._loop.stop)

    async def _handle(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        try:
            head = await asyncio.wait_for(reader.readuntil(b"\r\n\r\n"), HEAD_TIMEOUT_S)
        except (asyncio.IncompleteReadError, asyncio.LimitOverrunError, TimeoutError, ConnectionError):
            writer.close()
            return
        if len(head) > HEAD_LIMIT:
            await self._refuse(writer, "431 Request Header Fields Too Large")
            return
        from_query, from_cookie = _token_of(head)
        principal = await asyncio.to_thread(self._auth.resolve, from_query or from_cookie)
        if principal is None or principal.role < Role.viewer:
            await self._refuse(writer, "401 Unauthorized", self._how_to_open())
            return
        if from_query and self._auth.enabled:  # keep the token out of the page URL: store it in a cookie
            cookie = f"{COOKIE}={from_query}; HttpOnly; SameSite=Strict; Path=/"
            writer.write(_answer("303 See Other", {"Location": _without_token(head), "Set-Cookie": cookie}))
            await writer.drain()
            writer.close()
            return
        private = self._private
        if private is None:
            await self._answer(writer, self._starting_page(head))
            return
        await self._splice(head, reader, writer, principal, private)

    def _how_to_open(self) -> bytes:
        title = f"acs-twin {self._role} monitor"
        return _page(
            "401 Unauthorized",
            title,
            "<p>This monitor needs an API token (role viewer or above): open it once as "
            "<code>…/?token=&lt;API token&gt;</code>; the browser keeps it for the session.</p>",
        )

    def _starting_page(self, head: bytes) -> bytes:
        if b"\r\nupgrade:" in head.lower():  # a WebSocket before the monitor is up: nothing to splice to yet
            return _answer("503 Service Unavailable", {"Retry-After": str(STARTING_REFRESH_S)})
        waited = time.monotonic() - self._started
        return _page(
            "503 Service Unavailable",
            f"acs-twin {self._role} monitor",
            f"<progress></progress><p>starting: {html.escape(self._progress())} ({waited:.0f} s)</p>"
            "<p><small>This page turns into the monitor by itself once it is up.</small></p>",
            refresh_s=STARTING_REFRESH_S,
        )

    async def _answer(self, writer: asyncio.StreamWriter, answer: bytes) -> None:
        writer.write(answer)
        with contextlib.suppress(ConnectionError):
            await writer.drain()
        writer.close()

    async def _refuse(self, writer: asyncio.StreamWriter, status: str, answer: bytes | None = None) -> None:
        self.refused += 1
        writer.write(answer or _answer(status))
        with contextlib.suppress(ConnectionError):
            await writer.drain()
        writer.close()

    async def _splice(
        self,
        head: bytes,
        reader: asyncio.StreamReader,
        writer: asyncio.StreamWriter,
        principal: Principal,
        private_port: int,
    ) -> None:
        try:
            upstream_reader, upstream_writer = await asyncio.open_connection("127.0.0.1", private_port)
        except OSError:
            await self._refuse(writer, "502 Bad Gateway")
            return
        upstream_writer.write(head)
        pipes = [
            asyncio.ensure_future(self._pipe(reader, upstream_writer)),
            asyncio.ensure_future(self._pipe(upstream_reader, writer)),
        ]
        loop = asyncio.get_running_loop()

        def revoked() -> None:  # from the revoking thread: cancel the pipes on this loop
            loop.call_soon_threadsafe(_cancel, pipes)

        unwatch = self._auth.watch(principal, revoked)
        try:
            await asyncio.wait(pipes, return_when=asyncio.FIRST_COMPLETED)
        finally:
            unwatch()
            _cancel(pipes)
            for w in (writer, upstream_writer):
                w.close()

    @staticmethod
    async def _pipe(source: asyncio.StreamReader, sink: asyncio.StreamWriter) -> None:
        while data := await source.read(SPLICE_BYTES):
            sink.write(data)
            await sink.drain()


def _cancel(tasks: Sequence[asyncio.Future[None]]) -> None:
    for task in tasks:
        task.cancel()
