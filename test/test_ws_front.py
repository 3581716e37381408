"""The live view lets in Foxglove clients of both protocol names (issue 50): a real
foxglove-sdk server behind ros/ws_front.py, real WebSocket clients offering foxglove.sdk.v1,
the older foxglove.websocket.v1, both, or neither."""

import asyncio
import json
import socket
import threading
import time

import pytest

pytest.importorskip("foxglove", reason="foxglove-sdk is not installed (run the setup command)")
websockets = pytest.importorskip("websockets", reason="websockets is not installed (run the setup command)")

from websockets.exceptions import InvalidStatus  # noqa: E402

from sparse_body.ros.live_view import LiveView, LiveViewError  # noqa: E402
from sparse_body.ros.ws_front import translate_reply, translate_request  # noqa: E402

LIMIT = 30.0  # s: a busy machine answers late, never wrongly


@pytest.fixture
def live_view():
    view = LiveView("127.0.0.1", 0, "<robot name='body'/>")
    stop = threading.Event()

    def describe():  # as the node does, every so often
        while not stop.wait(0.1):
            view.log_description(time.time())

    logger = threading.Thread(target=describe, daemon=True)
    logger.start()
    yield view
    stop.set()
    logger.join()
    view.close()


async def first_ops(port: int, offered: list[str]) -> tuple[str | None, list[str]]:
    """The subprotocol the server chose and the ops of its first text frames (serverInfo,
    advertise) for a client offering `offered`."""
    async with websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=offered, open_timeout=LIMIT) as ws:
        ops = []
        while "advertise" not in ops:
            frame = await asyncio.wait_for(ws.recv(), timeout=LIMIT)
            if isinstance(frame, str):
                ops.append(json.loads(frame)["op"])
        return ws.subprotocol, ops


@pytest.mark.parametrize(
    "offered, chosen",
    [
        (["foxglove.sdk.v1"], "foxglove.sdk.v1"),
        (["foxglove.websocket.v1"], "foxglove.websocket.v1"),  # an older Foxglove or Lichtblick
        (["foxglove.websocket.v1", "foxglove.sdk.v1"], "foxglove.sdk.v1"),
    ],
)
def test_clients_of_either_protocol_name_are_served(live_view, offered, chosen):
    subprotocol, ops = asyncio.run(first_ops(live_view.port, offered))
    assert subprotocol == chosen
    assert ops[0] == "serverInfo" and "advertise" in ops


def test_a_client_of_another_protocol_is_refused_and_the_view_goes_on(live_view):
    with pytest.raises(InvalidStatus):
        asyncio.run(first_ops(live_view.port, ["chat.v2"]))
    # a client that connects and says nothing holds only its own connection
    with socket.create_connection(("127.0.0.1", live_view.port)):
        assert asyncio.run(first_ops(live_view.port, ["foxglove.websocket.v1"]))[0] == "foxglove.websocket.v1"


def test_the_handshake_is_translated_both_ways_and_only_for_the_legacy_name():
    legacy = b"GET / HTTP/1.1\r\nHost: x\r\nSec-WebSocket-Protocol: foxglove.websocket.v1\r\n\r\n"
    request, translated = translate_request(legacy)
    assert translated and b"Sec-WebSocket-Protocol: foxglove.sdk.v1\r\n" in request
    both = b"GET / HTTP/1.1\r\nsec-websocket-protocol: foxglove.websocket.v1, foxglove.sdk.v1\r\n\r\n"
    assert translate_request(both) == (both, False)
    plain = b"GET / HTTP/1.1\r\nHost: x\r\n\r\n"
    assert translate_request(plain) == (plain, False)
    reply = b"HTTP/1.1 101 Switching Protocols\r\nSec-WebSocket-Protocol: foxglove.sdk.v1\r\n\r\n"
    assert b"Sec-WebSocket-Protocol: foxglove.websocket.v1\r\n" in translate_reply(reply)
    refused = b"HTTP/1.1 400 Bad Request\r\n\r\n"
    assert translate_reply(refused) == refused


def test_a_taken_port_is_a_one_line_error_and_frees_the_inner_server():
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        with pytest.raises(LiveViewError, match="cannot serve on 127.0.0.1") as err:
            LiveView("127.0.0.1", taken.getsockname()[1], "<robot/>")
    assert "\n" not in str(err.value)
