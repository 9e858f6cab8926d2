"""A minimal Foxglove WebSocket client for the tests (the ``websockets`` package).

Written from the protocol (foxglove ws-protocol v1 framing, subprotocol
``foxglove.sdk.v1`` as foxglove-sdk >= 0.30 speaks it), not from pneu's
server: text ops ``serverInfo`` / ``advertise`` from the server, ``subscribe``
from the client, then binary MessageData frames
``u8 opcode 0x01 | u32 subscription id | u64 log time ns | payload`` (little endian).
Loaded by path (``importlib``) from the tests that need it.
"""

from __future__ import annotations

import contextlib
import json
import struct
import time

from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

SUBPROTOCOL = "foxglove.sdk.v1"
_MESSAGE_DATA = 0x01
_HEADER = struct.Struct("<BIQ")


class FoxgloveClient:
    def __init__(self, url: str, timeout_s: float = 20.0) -> None:
        self.timeout_s = timeout_s
        self._stack = contextlib.ExitStack()
        self.ws = self._stack.enter_context(
            connect(url, subprotocols=[SUBPROTOCOL], open_timeout=timeout_s)
        )
        assert self.ws.subprotocol == SUBPROTOCOL
        self.server_info: dict | None = None
        self.channels: dict[str, dict] = {}  # topic -> advertised channel
        self._subs: dict[int, str] = {}

    def wait_for_channels(self, topics) -> dict[str, dict]:
        """Read text ops until every topic in ``topics`` is advertised."""
        deadline = time.monotonic() + self.timeout_s
        while not set(topics) <= set(self.channels):
            op = json.loads(self.ws.recv(timeout=max(0.01, deadline - time.monotonic())))
            if op["op"] == "serverInfo":
                self.server_info = op
            elif op["op"] == "advertise":
                self.channels.update({c["topic"]: c for c in op["channels"]})
        return self.channels

    def subscribe(self, topics) -> None:
        subs = []
        for topic in topics:
            sub_id = len(self._subs) + 1
            self._subs[sub_id] = topic
            subs.append({"id": sub_id, "channelId": self.channels[topic]["id"]})
        self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))

    def messages(self, *, until_closed: bool = True, count: int | None = None) -> list:
        """[(topic, log_time_ns, payload)] until the server closes (or ``count`` arrived)."""
        out = []
        while count is None or len(out) < count:
            try:
                frame = self.ws.recv(timeout=self.timeout_s)
            except (ConnectionClosed, EOFError):
                if until_closed:
                    break
                raise
            if isinstance(frame, str):
                op = json.loads(frame)
                if op["op"] == "advertise":
                    self.channels.update({c["topic"]: c for c in op["channels"]})
                continue
            opcode, sub_id, log_time = _HEADER.unpack_from(frame)
            assert opcode == _MESSAGE_DATA, opcode
            out.append((self._subs[sub_id], log_time, bytes(frame[_HEADER.size :])))
        return out

    def close(self) -> None:
        self._stack.close()
