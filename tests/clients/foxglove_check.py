#!/usr/bin/env python3
"""Reads squall's Foxglove view as Foxglove would, written from the
Foxglove WebSocket protocol's specification and the MCAP format (the
`websockets` and `mcap` packages; no Foxglove SDK).

usage:
  foxglove_check.py live ws://HOST:PORT TOPIC...
      subscribes to every channel the server advertises and counts the
      messages of each until every TOPIC has one (or 60 s pass); prints
      {topic: {schema, encoding, messages, bytes}} as JSON.
  foxglove_check.py mcap FILE.mcap
      prints the same for a recorded file, from its summary and messages.
  foxglove_check.py stall ws://HOST:PORT SECS
      a viewer that stops reading: subscribes to every channel advertised
      in its first second, then reads nothing for SECS seconds, the
      connection held open (it answers no close, and its socket's small
      buffers fill). Prints "subscribed N".
"""

import asyncio
import json
import struct
import sys
import time

LIMIT_S = 60
SUBPROTOCOL = "foxglove.sdk.v1"
MESSAGE_DATA = 0x01


async def live(url, wanted):
    import websockets

    seen = {}
    by_subscription = {}
    next_id = 1
    deadline = time.monotonic() + LIMIT_S
    async with websockets.connect(url, subprotocols=[SUBPROTOCOL], max_size=None) as ws:
        while time.monotonic() < deadline:
            try:
                frame = await asyncio.wait_for(ws.recv(), timeout=max(0.1, deadline - time.monotonic()))
            except (asyncio.TimeoutError, websockets.ConnectionClosed):
                break
            if isinstance(frame, str):
                message = json.loads(frame)
                if message.get("op") == "advertise":
                    subscriptions = []
                    for channel in message["channels"]:
                        by_subscription[next_id] = channel
                        seen.setdefault(channel["topic"], {
                            "schema": channel.get("schemaName"),
                            "encoding": channel.get("encoding"),
                            "messages": 0,
                            "bytes": 0,
                        })
                        subscriptions.append({"id": next_id, "channelId": channel["id"]})
                        next_id += 1
                    await ws.send(json.dumps({"op": "subscribe", "subscriptions": subscriptions}))
                continue
            if frame[0] != MESSAGE_DATA:
                continue
            subscription, _log_time = struct.unpack_from("<IQ", frame, 1)
            channel = by_subscription.get(subscription)
            if channel is None:
                sys.exit(f"message data for unknown subscription {subscription}")
            entry = seen[channel["topic"]]
            entry["messages"] += 1
            entry["bytes"] += len(frame) - 13
            if all(seen.get(t, {}).get("messages", 0) > 0 for t in wanted):
                break
    print(json.dumps(seen))
    missing = [t for t in wanted if seen.get(t, {}).get("messages", 0) == 0]
    if missing:
        sys.exit(f"no messages on {missing}")


def stall(url, secs):
    """A client of raw sockets, so that nothing reads for it: the
    WebSocket handshake, the first frames (the advertisements), one
    subscribe per channel, then silence, the socket open."""
    import base64
    import os
    import socket
    import urllib.parse

    parts = urllib.parse.urlparse(url)
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    sock.connect((parts.hostname, parts.port))
    key = base64.b64encode(os.urandom(16)).decode()
    sock.sendall((f"GET / HTTP/1.1\r\nHost: {parts.netloc}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                  f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n"
                  f"Sec-WebSocket-Protocol: {SUBPROTOCOL}\r\n\r\n").encode())
    buffer = b""
    while b"\r\n\r\n" not in buffer:
        buffer += sock.recv(4096)
    buffer = buffer.split(b"\r\n\r\n", 1)[1]

    def send_text(text):
        payload = text.encode()
        mask = os.urandom(4)
        header = bytes([0x81])
        if len(payload) < 126:
            header += bytes([0x80 | len(payload)])
        else:
            header += bytes([0x80 | 126]) + struct.pack(">H", len(payload))
        sock.sendall(header + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(payload)))

    # Subscribe to what is advertised until the scans are (a source may
    # hold its first scans while it learns its laser's clock, and the view
    # advertises a topic with its first message), then a second more.
    subscribed, topics = 0, set()
    sock.settimeout(0.2)
    end = time.monotonic() + 30.0
    while time.monotonic() < end:
        if "/scan" in topics:
            end = min(end, time.monotonic() + 1.0)
        try:
            buffer += sock.recv(65536)
        except socket.timeout:
            pass
        while len(buffer) >= 2:
            opcode, length, at = buffer[0] & 0x0F, buffer[1] & 0x7F, 2
            if length == 126:
                if len(buffer) < 4:
                    break
                length, at = struct.unpack_from(">H", buffer, 2)[0], 4
            elif length == 127:
                if len(buffer) < 10:
                    break
                length, at = struct.unpack_from(">Q", buffer, 2)[0], 10
            if len(buffer) < at + length:
                break
            frame, buffer = buffer[at:at + length], buffer[at + length:]
            if opcode == 0x1 and json.loads(frame).get("op") == "advertise":
                channels = json.loads(frame)["channels"]
                topics.update(c["topic"] for c in channels)
                subscriptions = [{"id": subscribed + i + 1, "channelId": c["id"]} for i, c in enumerate(channels)]
                subscribed += len(subscriptions)
                send_text(json.dumps({"op": "subscribe", "subscriptions": subscriptions}))
    print(f"subscribed {subscribed}", flush=True)
    time.sleep(secs)


def recorded(path):
    from mcap.reader import make_reader

    seen = {}
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        if summary is None:
            sys.exit(f"{path}: no summary (the file was not finished)")
        for schema, channel, message in reader.iter_messages():
            entry = seen.setdefault(channel.topic, {
                "schema": schema.name if schema else None,
                "encoding": channel.message_encoding,
                "messages": 0,
                "bytes": 0,
            })
            entry["messages"] += 1
            entry["bytes"] += len(message.data)
        counted = summary.statistics.channel_message_counts
        for channel_id, channel in summary.channels.items():
            if counted.get(channel_id, 0) != seen.get(channel.topic, {}).get("messages", 0):
                sys.exit(f"{channel.topic}: the summary counts {counted.get(channel_id)}, the file holds "
                         f"{seen.get(channel.topic, {}).get('messages', 0)}")
    print(json.dumps(seen))


if __name__ == "__main__":
    if len(sys.argv) >= 3 and sys.argv[1] == "live":
        asyncio.run(live(sys.argv[2], sys.argv[3:]))
    elif len(sys.argv) == 3 and sys.argv[1] == "mcap":
        recorded(sys.argv[2])
    elif len(sys.argv) == 4 and sys.argv[1] == "stall":
        stall(sys.argv[2], float(sys.argv[3]))
    else:
        sys.exit(__doc__)
