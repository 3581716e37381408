"""The live view's door: one listening socket that lets in clients of both names of the Foxglove
WebSocket protocol.

foxglove-sdk's server accepts only the subprotocol `foxglove.sdk.v1`; clients written before it
(older Foxglove and Lichtblick releases, roslibjs-foxglove, scripts) offer only
`foxglove.websocket.v1` and get HTTP 400. The two are the same protocol under two names (the
SDK's maintainers say so; nothing after the handshake differs), so this front reads each
client's upgrade request, offers the SDK server the name it knows, gives the client back the
name it offered, and then copies bytes both ways. The SDK server itself listens on loopback
only, on a port of the operating system's choosing."""

from __future__ import annotations

import contextlib
import re
import selectors
import socket
import threading

SDK_PROTOCOL = b"foxglove.sdk.v1"
LEGACY_PROTOCOL = b"foxglove.websocket.v1"
HEAD_LIMIT = 16 * 1024  # bytes of an HTTP upgrade request or response head; more is not a client of ours
HANDSHAKE_TIMEOUT = 5.0  # s a client has to send its request head (a silent one holds only its own thread)
_PROTOCOL_LINE = re.compile(rb"(?im)^sec-websocket-protocol:[ \t]*([^\r\n]*)\r\n")


class WebSocketFront:
    """Listens on host:port (0: any free port) and hands each connection to the server at
    127.0.0.1:backend_port, translating the legacy subprotocol name in the handshake."""

    def __init__(self, host: str, port: int, backend_port: int) -> None:
        self.backend_port = backend_port
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        self._listener = socket.socket(family, socket.SOCK_STREAM)
        try:
            self._listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            self._listener.bind((host, port))
            self._listener.listen(16)
        except OSError:
            self._listener.close()
            raise
        self.port = int(self._listener.getsockname()[1])
        self._stopped = threading.Event()
        self._connections: set[socket.socket] = set()
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._accept, name="live-view-front", daemon=True)
        self._thread.start()

    def _accept(self) -> None:
        while not self._stopped.is_set():
            try:
                client, _ = self._listener.accept()
            except OSError:
                return  # closed by stop()
            threading.Thread(target=self._serve, args=(client,), name="live-view-client", daemon=True).start()

    def _track(self, *sockets: socket.socket, add: bool = True) -> None:
        with self._lock:
            for s in sockets:
                (self._connections.add if add else self._connections.discard)(s)

    def _serve(self, client: socket.socket) -> None:
        backend = None
        self._track(client)
        try:
            client.settimeout(HANDSHAKE_TIMEOUT)
            head, rest = _read_head(client)
            if head is None:
                return
            request, legacy = translate_request(head)
            backend = socket.create_connection(("127.0.0.1", self.backend_port), timeout=HANDSHAKE_TIMEOUT)
            self._track(backend)
            backend.sendall(request + rest)
            reply, after = _read_head(backend)
            if reply is None:
                return
            client.sendall((translate_reply(reply) if legacy else reply) + after)
            client.settimeout(None)
            backend.settimeout(None)
            _relay(client, backend, self._stopped)
        except OSError:
            pass  # a client that went away, or a server stopping: its connection ends, nothing else
        finally:
            for s in (client, backend):
                if s is not None:
                    self._track(s, add=False)
                    with contextlib.suppress(OSError):
                        s.close()

    def stop(self) -> None:
        self._stopped.set()
        with contextlib.suppress(OSError):
            self._listener.shutdown(socket.SHUT_RDWR)
        self._listener.close()
        with self._lock:
            live = list(self._connections)
        for s in live:
            with contextlib.suppress(OSError):
                s.shutdown(socket.SHUT_RDWR)
        self._thread.join(timeout=2.0)


def translate_request(head: bytes) -> tuple[bytes, bool]:
    """The upgrade request as the SDK server takes it, and whether the client offered only the
    legacy name (then the reply must name it)."""
    match = _PROTOCOL_LINE.search(head)
    if match is None:
        return head, False
    offered = [p.strip() for p in match.group(1).split(b",")]
    if SDK_PROTOCOL in offered or LEGACY_PROTOCOL not in offered:
        return head, False
    named = b", ".join(SDK_PROTOCOL if p == LEGACY_PROTOCOL else p for p in offered)
    return head[: match.start(1)] + named + head[match.end(1) :], True


def translate_reply(head: bytes) -> bytes:
    """The SDK server's reply with the subprotocol named as the legacy client offered it."""
    match = _PROTOCOL_LINE.search(head)
    if match is None or match.group(1).strip() != SDK_PROTOCOL:
        return head
    return head[: match.start(1)] + LEGACY_PROTOCOL + head[match.end(1) :]


def _read_head(sock: socket.socket) -> tuple[bytes | None, bytes]:
    """An HTTP head (through its blank line) and the bytes read after it; None when the peer
    closed first or sent more than HEAD_LIMIT without one."""
    data = b""
    while b"\r\n\r\n" not in data:
        if len(data) > HEAD_LIMIT:
            return None, b""
        chunk = sock.recv(4096)
        if not chunk:
            return None, b""
        data += chunk
    end = data.index(b"\r\n\r\n") + 4
    return data[:end], data[end:]


def _relay(a: socket.socket, b: socket.socket, stopped: threading.Event) -> None:
    """Bytes both ways until either side closes."""
    with selectors.DefaultSelector() as selector:
        selector.register(a, selectors.EVENT_READ, b)
        selector.register(b, selectors.EVENT_READ, a)
        while not stopped.is_set():
            for key, _ in selector.select(timeout=0.5):
                data = key.fileobj.recv(65536)  # type: ignore[union-attr]
                if not data:
                    return
                key.data.sendall(data)
