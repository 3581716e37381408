"""`sparse-body view ws://HOST:PORT`: a few seconds of the live view, as a page.

The estimator node's `foxglove_port` serves its outputs over the Foxglove WebSocket protocol
(ros/live_view.py). This is a client of that protocol, as the Foxglove app is: it subscribes
to /tf and keeps what comes for the given seconds, which `view` draws like an estimate bag
(the body from its links, the trackers as `<frame>_seen`). A user without the app, or on a
machine without a display, sees what the node estimates; a page can be sent to someone."""

from __future__ import annotations

import asyncio
import json
import struct
import time

from ..io.cdr import MalformedMessage, TfRow, read_tf
from .viewer import ViewError

SUBPROTOCOL = "foxglove.sdk.v1"  # what foxglove-sdk's server speaks (the node's live view)
# and what foxglove_bridge and older servers speak: the same advertise, subscribe and message ops
LEGACY_SUBPROTOCOL = "foxglove.websocket.v1"
MESSAGE_DATA = 1  # the binary opcode of a message: opcode, subscription id (u32), log time (u64), payload
CONNECT_TIMEOUT = 10.0  # s
MAX_SECONDS = 600.0  # a page holds at most this much (view's MAX_FRAMES at 30 frames drawn a second is 300 s)


def record_tf(url: str, seconds: float) -> tuple[list[list[TfRow]], int]:
    """(the /tf messages the live view at url sent in seconds, how many were not TFMessages)."""
    if not 0.0 < seconds <= MAX_SECONDS:
        raise ViewError(f"seconds must be between 0 and {MAX_SECONDS:g}, got {seconds}")
    try:
        return asyncio.run(_record(url, seconds))
    except (OSError, TimeoutError) as err:
        raise ViewError(f"{url}: no live view there ({err}); is the estimator's foxglove_port set?") from None


async def _record(url: str, seconds: float) -> tuple[list[list[TfRow]], int]:
    import websockets
    from websockets.typing import Subprotocol

    messages: list[list[TfRow]] = []
    malformed = 0
    try:
        ws = await websockets.connect(
            url, subprotocols=[Subprotocol(SUBPROTOCOL), Subprotocol(LEGACY_SUBPROTOCOL)], open_timeout=CONNECT_TIMEOUT
        )
    except websockets.exceptions.WebSocketException as err:
        raise ViewError(f"{url}: not a Foxglove live view ({err})") from None
    async with ws:
        subscription = None
        end = time.monotonic() + seconds
        while (left := end - time.monotonic()) > 0:
            try:
                frame = await asyncio.wait_for(ws.recv(), timeout=left)
            except TimeoutError:
                break
            except websockets.exceptions.ConnectionClosed:  # the node stopped: keep what came
                break
            if isinstance(frame, str):
                channel = _advertised_tf(frame)
                if channel is None:
                    malformed += not _is_json_object(frame)  # another op is fine; a broken text is not
                elif subscription is None:
                    subscription = 1
                    await ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": channel}]}))
            elif len(frame) > 13 and frame[0] == MESSAGE_DATA and struct.unpack_from("<I", frame, 1)[0] == subscription:
                try:
                    messages.append(read_tf(bytes(frame[13:])))
                except MalformedMessage:
                    malformed += 1
    if subscription is None:
        raise ViewError(f"{url}: the live view offered no /tf in {seconds:g} s")
    return messages, malformed


def _is_json_object(text: str) -> bool:
    try:
        return isinstance(json.loads(text), dict)
    except (ValueError, RecursionError):
        return False


def _advertised_tf(text: str) -> int | None:
    """The channel id of a CDR /tf channel that a text frame advertises, None for anything else
    (another op, JSON of another shape, no JSON at all: a server is not trusted to be ours)."""
    try:
        op = json.loads(text)
    except (ValueError, RecursionError):
        return None
    if not isinstance(op, dict) or op.get("op") != "advertise" or not isinstance(op.get("channels"), list):
        return None
    for channel in op["channels"]:
        if (
            isinstance(channel, dict)
            and channel.get("topic") == "/tf"
            and channel.get("encoding") == "cdr"
            and isinstance(channel.get("id"), int)
            and not isinstance(channel.get("id"), bool)
        ):
            return channel["id"]
    return None
