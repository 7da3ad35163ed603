"""An independent ROS 2 robot for squall's live link, written from
rmw_zenoh's design (docs/design.md, liveliness_utils.cpp,
attachment_helpers.cpp, qos.cpp) with the eclipse-zenoh Python package:
no squall code. Messages are encoded and decoded with the `rosbags`
package, type hashes computed by it, GIDs with `xxhash`.

    python3 ros2_robot.py --connect tcp/127.0.0.1:7450 --scans 60

It finds squall's node through the `@ros2_lv` liveliness tokens (and
waits for its `/scan` subscription before driving), announces its own
node, publishers and subscriptions the same way, publishes `/scan` and
`/odom` (or, with `--odometry tf`, `odom -> base_link` on `/tf`) with
rmw_zenoh's attachment on every sample, drives 0.5 m/s along a straight
corridor (walls 2 m to each side), 10 scans a second, and checks every
sample squall sends back (`/pose`, `/tf`, and `/map` taken by a
subscriber that joins late, as a transient-local one does). Prints one
JSON line with what it found.
"""

import argparse
import json
import math
import struct
import threading
import time

import numpy as np
import xxhash
import zenoh
import zenoh.ext
from rosbags.typesys import Stores, get_typestore

TS = get_typestore(Stores.ROS2_JAZZY)
T = TS.types
DOMAIN = 0


def dds_name(typename):
    pkg, kind, name = typename.split("/")
    return f"{pkg}::{kind}::dds_::{name}_"


def topic_key(topic, typename):
    return f"{DOMAIN}/{topic.strip('/')}/{dds_name(typename)}/{TS.hash_rihs01(typename)}"


def mangle(s):
    return s.replace("/", "%") if s else "%"


def qos_key(depth, transient_local=False):
    # R:D:H,depth:DLs,DLns:LSs,LSns:LV,LVs,LVns, empty where rmw_zenoh's
    # default (reliable, volatile, keep-last, 42, infinite, automatic).
    return f":{'1' if transient_local else ''}:,{'' if depth == 42 else depth}:,:,:,,"


class Node:
    """A node's tokens and its entity ids, as rmw_zenoh declares them."""

    def __init__(self, session, name):
        self.session, self.name = session, name
        self.zid = str(session.info.zid())
        self.next_id = 1
        self.tokens = [session.liveliness().declare_token(f"@ros2_lv/{DOMAIN}/{self.zid}/0/0/NN/%/%/{name}")]

    def entity(self, kind, topic, typename, qos):
        key = (
            f"@ros2_lv/{DOMAIN}/{self.zid}/0/{self.next_id}/{kind}/%/%/{self.name}/"
            f"{mangle(topic)}/{dds_name(typename)}/{TS.hash_rihs01(typename)}/{qos}"
        )
        self.next_id += 1
        self.tokens.append(self.session.liveliness().declare_token(key))
        return key


class Publisher:
    """A publisher that sends rmw_zenoh's attachment with every sample."""

    def __init__(self, node, topic, typename):
        token = node.entity("MP", topic, typename, qos_key(10))
        self.gid = xxhash.xxh3_128_intdigest(token).to_bytes(16, "little")
        self.typename = typename
        self.publisher = node.session.declare_publisher(topic_key(topic, typename))
        self.seq = 0

    def put(self, msg):
        self.seq += 1
        attachment = struct.pack("<qqB", self.seq, time.time_ns(), 16) + self.gid
        payload = bytes(TS.serialize_cdr(msg, self.typename))
        self.publisher.put(payload, attachment=attachment)


def parse_token(key):
    """A liveliness token's fields, or None if it is not an entity's."""
    parts = key.split("/")
    if len(parts) < 9 or parts[0] != "@ros2_lv":
        return None
    entity = {"domain": parts[1], "zid": parts[2], "kind": parts[5], "node": parts[8], "key": key}
    if entity["kind"] in ("MP", "MS") and len(parts) >= 13:
        entity.update(topic=parts[9].replace("%", "/"), type=parts[10], hash=parts[11], qos=parts[12])
    return entity


class AttachmentCheck:
    """Every sample squall sends must carry rmw_zenoh's attachment: 33
    bytes, sequence numbers from 1 without gaps per publisher (squall
    publishes poses and transforms only to listeners, so this client,
    listening from the start, sees them all; the map's cache gives a late
    subscriber the last one), a source time near now, and the GID of the
    publisher's token."""

    def __init__(self, gids):
        self.gids, self.last_seq, self.errors, self.samples = gids, {}, [], 0
        self.lock = threading.Lock()

    def check(self, topic, sample):
        with self.lock:
            self.samples += 1
            a = sample.attachment
            raw = bytes(a.to_bytes()) if a is not None else b""
            if len(raw) != 33 or raw[16] != 16:
                self.errors.append(f"{topic}: attachment of {len(raw)} bytes")
                return
            seq, stamp_ns = struct.unpack_from("<qq", raw, 0)
            gid = raw[17:]
            if gid != self.gids.get(topic):
                self.errors.append(f"{topic}: GID {gid.hex()} is not the hash of squall's token")
            # From 1, one by one; a transient-local subscriber's first
            # sample is the cached one, whatever its number.
            previous = self.last_seq.get(gid)
            expected = previous + 1 if previous is not None else None if topic == "/map" else 1
            if seq < 1 or (expected is not None and seq != expected):
                self.errors.append(f"{topic}: sequence {seq} after {previous}")
            self.last_seq[gid] = seq
            if abs(stamp_ns - time.time_ns()) > 60e9:
                self.errors.append(f"{topic}: source time {stamp_ns} ns is not now")


def header(stamp, frame):
    sec = math.floor(stamp)
    return T["std_msgs/msg/Header"](
        stamp=T["builtin_interfaces/msg/Time"](sec=sec, nanosec=round((stamp - sec) * 1e9)), frame_id=frame
    )


def quaternion(theta):
    return T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(theta / 2), w=math.cos(theta / 2))


def yaw(q):
    return math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))


def laser_scan(stamp, ranges):
    return T["sensor_msgs/msg/LaserScan"](
        header=header(stamp, "laser"),
        angle_min=-math.pi / 2,
        angle_max=math.pi / 2,
        angle_increment=math.pi / 180,
        time_increment=0.0,
        scan_time=0.0,
        range_min=0.05,
        range_max=30.0,
        ranges=np.array(ranges, dtype=np.float32),
        intensities=np.array([], dtype=np.float32),
    )


def odometry(stamp, x):
    pose = T["geometry_msgs/msg/Pose"](
        position=T["geometry_msgs/msg/Point"](x=x, y=0.0, z=0.0), orientation=quaternion(0.0)
    )
    twist = T["geometry_msgs/msg/Twist"](
        linear=T["geometry_msgs/msg/Vector3"](x=0.5, y=0.0, z=0.0),
        angular=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
    )
    return T["nav_msgs/msg/Odometry"](
        header=header(stamp, "odom"),
        child_frame_id="base_link",
        pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
        twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=np.zeros(36)),
    )


def odom_transform(stamp, x):
    transform = T["geometry_msgs/msg/Transform"](
        translation=T["geometry_msgs/msg/Vector3"](x=x, y=0.0, z=0.0), rotation=quaternion(0.0)
    )
    stamped = T["geometry_msgs/msg/TransformStamped"](
        header=header(stamp, "odom"), child_frame_id="base_link", transform=transform
    )
    return T["tf2_msgs/msg/TFMessage"](transforms=[stamped])


def corridor_ranges(y, beams=181):
    """Ranges from (x, y) heading +x to walls at y = +-2 (30 m cap)."""
    out = []
    for i in range(beams):
        a = -math.pi / 2 + i * math.pi / (beams - 1)
        s = math.sin(a)
        r = 30.0
        if s > 1e-9:
            r = min(r, (2.0 - y) / s)
        elif s < -1e-9:
            r = min(r, (-2.0 - y) / s)
        out.append(r)
    return out


def stamp_of(h):
    return round(h.stamp.sec + h.stamp.nanosec * 1e-9, 6)


def discover(session, deadline):
    """squall's entities, once its node subscribes to /scan."""
    while time.time() < deadline:
        entities = []
        for reply in session.liveliness().get(f"@ros2_lv/{DOMAIN}/**", timeout=2.0):
            if reply.ok is not None:
                e = parse_token(str(reply.ok.key_expr))
                if e is not None and e["node"] == "squall":
                    entities.append(e)
        if any(e["kind"] == "MS" and e.get("topic") == "/scan" for e in entities):
            return entities
        time.sleep(0.1)
    raise SystemExit("squall's node did not appear in the ROS graph (no @ros2_lv token with /scan)")


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--connect", required=True)
    p.add_argument("--scans", type=int, default=60)
    p.add_argument("--odometry", choices=["odom", "tf"], default="odom")
    p.add_argument("--ignore-poses", action="store_true", help="do not subscribe to the poses")
    args = p.parse_args()
    config = zenoh.Config()
    config.insert_json5("mode", '"peer"')
    config.insert_json5("connect/endpoints", json.dumps([args.connect]))
    config.insert_json5("scouting/multicast/enabled", "false")
    poses, transforms = {}, {}
    with zenoh.open(config) as session:
        entities = discover(session, time.time() + 20)
        mine = {(e["kind"], e.get("topic")): e for e in entities}
        gids = {
            topic: xxhash.xxh3_128_intdigest(mine[("MP", topic)]["key"]).to_bytes(16, "little")
            for topic in ("/pose", "/tf", "/map")
            if ("MP", topic) in mine
        }
        check = AttachmentCheck(gids)
        node = Node(session, "py_robot")

        def on_pose(sample):
            check.check("/pose", sample)
            msg = TS.deserialize_cdr(bytes(sample.payload.to_bytes()), "geometry_msgs/msg/PoseStamped")
            pos = msg.pose.position
            poses[stamp_of(msg.header)] = (msg.header.frame_id, pos.x, pos.y, yaw(msg.pose.orientation))

        def on_tf(sample):
            msg = TS.deserialize_cdr(bytes(sample.payload.to_bytes()), "tf2_msgs/msg/TFMessage")
            for t in msg.transforms:
                if (t.header.frame_id, t.child_frame_id) == ("map", "odom"):
                    check.check("/tf", sample)
                    v = t.transform.translation
                    transforms[stamp_of(t.header)] = (v.x, v.y, yaw(t.transform.rotation))

        subscribers = []
        if not args.ignore_poses:
            node.entity("MS", "/pose", "geometry_msgs/msg/PoseStamped", qos_key(10))
            subscribers.append(
                session.declare_subscriber(topic_key("/pose", "geometry_msgs/msg/PoseStamped"), on_pose)
            )
            node.entity("MS", "/tf", "tf2_msgs/msg/TFMessage", qos_key(100))
            subscribers.append(session.declare_subscriber(topic_key("/tf", "tf2_msgs/msg/TFMessage"), on_tf))
        scan_pub = Publisher(node, "/scan", "sensor_msgs/msg/LaserScan")
        if args.odometry == "odom":
            odom_pub = Publisher(node, "/odom", "nav_msgs/msg/Odometry")
        else:
            odom_pub = Publisher(node, "/tf", "tf2_msgs/msg/TFMessage")
        time.sleep(0.5)  # let squall's subscriptions see the new publishers
        t0 = 1000.0
        odom_x = {}
        for k in range(args.scans):
            stamp = t0 + 0.1 * k
            x = 0.05 * k
            odom_x[round(stamp, 6)] = x
            odom_pub.put(odometry(stamp, x) if args.odometry == "odom" else odom_transform(stamp, x))
            scan_pub.put(laser_scan(stamp, corridor_ranges(0.0)))
            time.sleep(0.1)
        # squall's live dispatcher may drop readings while its matchers are
        # busy (it counts them) but never the newest: the last scan's pose
        # comes, and poses come in order, so once it is here every pose
        # that will come has. (60 s only bounds a broken run.)
        last = round(t0 + 0.1 * (args.scans - 1), 6)
        deadline = time.time() + 60
        while not args.ignore_poses and last not in poses and time.time() < deadline:
            time.sleep(0.05)
        # A subscriber that joins after the maps were sent, transient-local
        # as rmw_zenoh declares it: it asks the publishers' caches.
        maps = []

        def on_map(sample):
            check.check("/map", sample)
            msg = TS.deserialize_cdr(bytes(sample.payload.to_bytes()), "nav_msgs/msg/OccupancyGrid")
            data = np.asarray(msg.data)
            maps.append(
                {
                    "frame": msg.header.frame_id,
                    "width": int(msg.info.width),
                    "height": int(msg.info.height),
                    "cells": int(data.size),
                    "known": int(np.count_nonzero(data >= 0)),
                    "occupied": int(np.count_nonzero(data >= 65)),
                    # squall stamps a map when it sends it: one sent before
                    # this subscriber existed came from the publisher's cache.
                    "sent_before_joining": stamp_of(msg.header) < joined,
                }
            )

        time.sleep(1.0)  # the last maps, if any, go out before it joins
        joined = time.time()
        node.entity("MS", "/map", "nav_msgs/msg/OccupancyGrid", qos_key(1, transient_local=True))
        late = zenoh.ext.declare_advanced_subscriber(
            session,
            topic_key("/map", "nav_msgs/msg/OccupancyGrid"),
            on_map,
            history=zenoh.ext.HistoryConfig(detect_late_publishers=True, max_samples=1),
            subscriber_detection=True,
        )
        deadline = time.time() + 10
        while not maps and time.time() < deadline:
            time.sleep(0.05)
        del late
    # The correction map -> odom composed with the odometry is the pose.
    tf_error = 0.0
    tf_matched = 0
    for stamp, (frame, x, y, theta) in poses.items():
        if stamp in transforms and stamp in odom_x:
            cx, cy, ct = transforms[stamp]
            ox = odom_x[stamp]
            px, py = cx + math.cos(ct) * ox, cy + math.sin(ct) * ox
            dt = math.atan2(math.sin(ct - theta), math.cos(ct - theta))
            tf_error = max(tf_error, math.hypot(px - x, py - y), abs(dt))
            tf_matched += 1
    last = max(poses.items())[1] if poses else None
    print(
        json.dumps(
            {
                "scans_sent": args.scans,
                "squall_entities": sorted(
                    f"{e['kind']} {e.get('topic', '')} {e.get('type', '')} {e.get('hash', '')} {e.get('qos', '')}".strip()
                    for e in entities
                ),
                "expected_hashes": {
                    t: TS.hash_rihs01(t)
                    for t in (
                        "sensor_msgs/msg/LaserScan",
                        "nav_msgs/msg/Odometry",
                        "tf2_msgs/msg/TFMessage",
                        "geometry_msgs/msg/PoseStamped",
                        "nav_msgs/msg/OccupancyGrid",
                    )
                },
                "poses_received": len(poses),
                "pose_frames": sorted({p[0] for p in poses.values()}),
                "last_pose": last,
                "transforms_received": len(transforms),
                "transforms_matched": tf_matched,
                "tf_max_error": tf_error,
                "samples_checked": check.samples,
                "attachment_errors": check.errors[:10],
                "late_map": maps[0] if maps else None,
            }
        )
    )


if __name__ == "__main__":
    main()
