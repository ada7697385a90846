"""Reads MCAP recordings with an independent reader (PyPI mcap + mcap-ros2-support, which
decodes CDR from the ros2msg schemas in the file) and prints, as JSON, per topic: the message
count, the schema name, and a few decoded fields of the last message.

    python tools/mcap_check.py FILE.mcap [FILE.mcap ...]
"""
import json
import math
import sys

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory


def summary(path):
    topics = {}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        header = reader.get_header()
        for schema, channel, message, msg in reader.iter_decoded_messages():
            t = topics.setdefault(channel.topic, {"count": 0, "schema": schema.name})
            t["count"] += 1
            t["log_time"] = message.log_time
            if channel.topic == "/scan":
                t["beams"] = len(msg.ranges)
                t["frame_id"] = msg.header.frame_id
                finite = [r for r in msg.ranges if math.isfinite(r)]
                t["min_range"] = min(finite) if finite else None
                t["range_max"] = msg.range_max
            elif channel.topic == "/odom":
                p = msg.pose.pose.position
                t["x"], t["y"] = p.x, p.y
                t["child_frame_id"] = msg.child_frame_id
                t["covariance_len"] = len(msg.pose.covariance)
            elif channel.topic == "/tf":
                t["frames"] = [[tr.header.frame_id, tr.child_frame_id] for tr in msg.transforms]
            elif channel.topic == "/cmd_vel":
                t["linear"], t["angular"] = msg.linear.x, msg.angular.z
            elif channel.topic == "/goal_pose":
                t["x"], t["y"] = msg.pose.position.x, msg.pose.position.y
            elif channel.topic == "/clock":
                t["sec"] = msg.clock.sec + msg.clock.nanosec * 1e-9
    return {"profile": header.profile, "topics": topics}


print(json.dumps({p: summary(p) for p in sys.argv[1:]}))
