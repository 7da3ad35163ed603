"""An independent robot client for squall's live link: the eclipse-zenoh
Python package publishing ROS 2 CDR LaserScan and Odometry messages
(encoded here with `struct`, not with squall's code) and reading the CDR
PoseStamped messages that come back.

    python3 cdr_robot.py --connect tcp/127.0.0.1:7450 --scans 60

Drives a robot along a straight corridor (walls 2 m to each side) at
0.5 m/s, 10 scans a second, and prints one JSON line: scans sent, poses
received, and the last pose.
"""

import argparse
import json
import math
import struct
import time

import zenoh


class Cdr:
    """Little-endian CDR, aligned relative to the data after the header."""

    def __init__(self):
        self.data = bytearray()

    def align(self, n):
        self.data += b"\0" * ((-len(self.data)) % n)

    def put(self, fmt, *values):
        self.align(struct.calcsize(fmt[-1]))
        self.data += struct.pack("<" + fmt, *values)

    def string(self, s):
        raw = s.encode() + b"\0"
        self.put("I", len(raw))
        self.data += raw

    def header(self, stamp, frame):
        sec = math.floor(stamp)
        self.put("i", sec)
        self.put("I", round((stamp - sec) * 1e9))
        self.string(frame)

    def bytes(self):
        return b"\x00\x01\x00\x00" + bytes(self.data)


def laser_scan(stamp, ranges, angle_min, angle_increment):
    c = Cdr()
    c.header(stamp, "laser")
    angle_max = angle_min + angle_increment * (len(ranges) - 1)
    for v in (angle_min, angle_max, angle_increment, 0.0, 0.0, 0.05, 30.0):
        c.put("f", v)
    c.put("I", len(ranges))
    for r in ranges:
        c.put("f", r)
    c.put("I", 0)  # no intensities
    return c.bytes()


def odometry(stamp, x, y, theta):
    c = Cdr()
    c.header(stamp, "odom")
    c.string("base_link")
    for v in (x, y, 0.0, 0.0, 0.0, math.sin(theta / 2), math.cos(theta / 2)):
        c.put("d", v)
    for _ in range(36 + 6 + 36):
        c.put("d", 0.0)
    return c.bytes()


def read_pose_stamped(payload):
    data = payload[4:]
    sec, nsec, n = struct.unpack_from("<iII", data, 0)
    at = 12 + n
    at += (-at) % 8
    x, y, _z, qx, qy, qz, qw = struct.unpack_from("<7d", data, at)
    theta = math.atan2(2 * (qw * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz))
    return sec + nsec * 1e-9, x, y, theta


def corridor_ranges(y, beams=181):
    """Ranges from (x, y) heading +x to walls at y = ±2 (30 m cap)."""
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


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--connect", required=True)
    p.add_argument("--scans", type=int, default=60)
    p.add_argument("--ignore-poses", action="store_true", help="do not subscribe to the poses")
    args = p.parse_args()
    config = zenoh.Config()
    config.insert_json5("mode", '"peer"')
    config.insert_json5("connect/endpoints", json.dumps([args.connect]))
    config.insert_json5("scouting/multicast/enabled", "false")
    poses = []
    with zenoh.open(config) as session:
        if not args.ignore_poses:
            session.declare_subscriber(
                "robot/pose", lambda s: poses.append(read_pose_stamped(bytes(s.payload.to_bytes())))
            )
        scan_publisher = session.declare_publisher("robot/scan")
        odom_publisher = session.declare_publisher("robot/odom")
        # Drive once the topology subscribes to the scans.
        deadline = time.time() + 20
        while not scan_publisher.matching_status.matching:
            if time.time() > deadline:
                raise SystemExit("no link to a topology taking scans at " + args.connect)
            time.sleep(0.02)
        t0 = 1000.0
        for k in range(args.scans):
            stamp = t0 + 0.1 * k
            x = 0.05 * k
            odom_publisher.put(odometry(stamp, x, 0.0, 0.0))
            scan_publisher.put(laser_scan(stamp, corridor_ranges(0.0), -math.pi / 2, math.pi / 180))
            time.sleep(0.1)
        deadline = time.time() + 5
        while not args.ignore_poses and len(poses) < args.scans and time.time() < deadline:
            time.sleep(0.05)
    last = poses[-1] if poses else None
    print(json.dumps({"scans_sent": args.scans, "poses_received": len(poses), "last_pose": last}))


if __name__ == "__main__":
    main()
