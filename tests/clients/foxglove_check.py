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
    else:
        sys.exit(__doc__)
