"""A minimal client of the Foxglove WebSocket protocol v1, independent of the foxglove-sdk (tests and bench).

Speaks the protocol with the ``websockets`` library and offers both subprotocol names,
``foxglove.websocket.v1`` (the ws-protocol spec) and ``foxglove.sdk.v1`` (the same protocol under the name
foxglove-sdk servers require since 2025; they reject the old name with HTTP 400 —
foxglove/ros-foxglove-bridge#382, lichtblick-suite/lichtblick#819). It reads the JSON
``serverInfo``/``advertise`` ops, sends ``subscribe``, and parses binary message-data frames (opcode 0x01,
uint32 subscription id, uint64 timestamp ns, payload). Protobuf payloads are decoded with the ``protobuf``
package against the FileDescriptorSet the server advertised. Spec:
github.com/foxglove/ws-protocol/blob/main/docs/spec.md.
"""

from __future__ import annotations

import asyncio
import base64
import json
import struct
import time

__all__ = ["SUBPROTOCOLS", "FoxgloveClient", "proto_class"]

SUBPROTOCOLS = ["foxglove.websocket.v1", "foxglove.sdk.v1"]


def proto_class(schema_b64: str, name: str):
    """Message class for ``name`` from an advertised base64 FileDescriptorSet."""
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

    fds = descriptor_pb2.FileDescriptorSet.FromString(base64.b64decode(schema_b64))
    pool = descriptor_pool.DescriptorPool()
    for f in fds.file:
        pool.Add(f)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(name))


class FoxgloveClient:
    """Minimal client of the Foxglove WebSocket protocol v1."""

    def __init__(self, ws) -> None:
        self.ws = ws
        self.channels: dict[str, dict] = {}
        self.subs: dict[int, dict] = {}
        self.server_info: dict | None = None
        #: the server times received (capability ``time``, binary opcode 0x02), ns, in arrival order
        self.times: list[int] = []

    @classmethod
    async def open(cls, port: int, host: str = "127.0.0.1") -> FoxgloveClient:
        """Connect to ``ws://host:port``; raises ``OSError``/``websockets`` errors if it cannot."""
        from websockets.asyncio.client import connect

        ws = await connect(f"ws://{host}:{port}", subprotocols=SUBPROTOCOLS, max_size=None)
        assert ws.subprotocol in SUBPROTOCOLS
        return cls(ws)

    async def wait_channels(self, topics: set[str], timeout: float = 5.0) -> None:
        deadline = time.monotonic() + timeout
        while not topics <= set(self.channels):
            await self._recv(deadline)

    async def subscribe(self, topics: list[str]) -> None:
        subs = []
        for i, t in enumerate(topics, start=len(self.subs) + 1):
            ch = self.channels[t]
            self.subs[i] = ch
            subs.append({"id": i, "channelId": ch["id"]})
        await self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))

    async def recv(self, deadline: float):
        """Next frame before ``deadline`` (monotonic s): (topic, timestamp ns, payload) for message data, None
        for a JSON op (advertise ops update ``channels``) or a server time (appended to ``times``). Raises
        ``TimeoutError``; ``ValueError`` for a binary opcode the protocol does not define."""
        return await self._recv(deadline)

    async def _recv(self, deadline: float):
        left = deadline - time.monotonic()
        if left <= 0:
            raise TimeoutError("no message in time")
        data = await asyncio.wait_for(self.ws.recv(), left)
        if isinstance(data, str):
            op = json.loads(data)
            if op["op"] == "advertise":
                for ch in op["channels"]:
                    self.channels[ch["topic"]] = ch
            elif op["op"] == "serverInfo":
                self.server_info = op
            return None
        if data[0] == 0x02:                           # Time: uint64 timestamp ns
            self.times.append(struct.unpack_from("<Q", data, 1)[0])
            return None
        if data[0] != 0x01:
            raise ValueError(f"unexpected binary opcode {data[0]}")
        sub_id, stamp_ns = struct.unpack_from("<IQ", data, 1)
        return self.subs[sub_id]["topic"], stamp_ns, data[13:]

    async def messages(self, want: dict[str, int], timeout: float = 10.0) -> dict[str, list[bytes]]:
        """Collect at least ``want[topic]`` payloads per topic."""
        got: dict[str, list[bytes]] = {t: [] for t in want}
        deadline = time.monotonic() + timeout
        while any(len(got[t]) < n for t, n in want.items()):
            m = await self._recv(deadline)
            if m is not None and m[0] in got:
                got[m[0]].append(m[2])
        return got

    def decode(self, topic: str, payload: bytes):
        ch = self.channels[topic]
        if ch["encoding"] == "json":
            return json.loads(payload)
        assert ch["encoding"] == "protobuf" and ch["schemaEncoding"] == "protobuf"
        return proto_class(ch["schema"], ch["schemaName"]).FromString(payload)
