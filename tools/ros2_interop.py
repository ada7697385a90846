"""Peers rlnav did not write, for the ROS 2 interoperability tests (crates/cli/tests/ros2.rs):
a real rclpy node (ROS 2 Jazzy, Fast DDS) and an Eclipse Cyclone DDS participant.

    python tools/ros2_interop.py MODE [--seconds S] [--ns /NAMESPACE]

Modes:
  rclpy-node    publish /scan and /odom, expect rlnav's node to answer on /cmd_vel, and find
                rlnav_policy and its topics with their types in the ROS graph
                (with --ns, the topics and the node in that namespace)
  rclpy-plan    as rclpy-node, for a node started without a goal: the goal comes as a
                nav_msgs/Path on /plan (what Nav2's planner server publishes), and /odom is
                published best effort (as a TurtleBot 4 does)
  rclpy-u-plan  with rlnav's sim bridge running crates/cli/tests/fixtures/u-dead-end.yaml and
                rlnav's node started without a goal: publish a nav_msgs/Path round the U-shaped
                dead end on /plan (frame odom, 5 cm spacing, re-sent every second as Nav2's
                planner server replans) and watch the bridge's /odom until the robot is within
                the goal tolerance of the path's end; report the final distance and the
                trajectory's closest approach to the U (--no-plan: publish no plan and report
                where the robot got to, the counterfactual)
  rclpy-sim     subscribe to the sim bridge's /scan, /odom and /goal_pose, check them, and drive
                the robot to the goal with a proportional controller on /cmd_vel
  cyclone-node  as rclpy-node, over Cyclone DDS with hand-declared ROS 2 types
  cyclone-sim   subscribe to the sim bridge's /scan and /odom over Cyclone DDS and check them

Prints one JSON object and exits 0 when every check passed, 1 otherwise. Set ROS_DOMAIN_ID;
keep traffic on loopback with ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST (rclpy) and the
CYCLONEDDS_URI this script sets itself (Cyclone).
"""
import argparse
import json
import math
import os
import sys
import time

BEAMS = 360


def result(ok, **fields):
    fields["ok"] = bool(ok)
    print(json.dumps(fields), flush=True)
    sys.exit(0 if ok else 1)


# ---------------------------------------------------------------- rclpy (ROS 2 Jazzy)

def rclpy_node(seconds, plan=False, ns=""):
    import rclpy
    from geometry_msgs.msg import PoseStamped, Twist
    from nav_msgs.msg import Odometry, Path
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import LaserScan

    rclpy.init()
    node = rclpy.create_node("interop_robot")
    scan_pub = node.create_publisher(LaserScan, ns + "/scan", qos_profile_sensor_data)
    # In plan mode odometry goes out best effort, as a TurtleBot 4 publishes it.
    odom_pub = node.create_publisher(Odometry, ns + "/odom", qos_profile_sensor_data if plan else 10)
    plan_pub = node.create_publisher(Path, ns + "/plan", 10)
    got = []
    node.create_subscription(Twist, ns + "/cmd_vel", lambda m: got.append((m.linear.x, m.angular.z)), 10)
    graph = {"node": False, "cmd_vel_type": None, "scan_type": None, "plan_type": None}
    end = time.time() + seconds
    while time.time() < end:
        now = node.get_clock().now().to_msg()
        s = LaserScan()
        s.header.stamp, s.header.frame_id = now, "laser"
        s.angle_min, s.angle_increment = -math.pi, 2 * math.pi / BEAMS
        s.angle_max = s.angle_min + s.angle_increment * (BEAMS - 1)
        s.range_min, s.range_max, s.scan_time = 0.05, 8.0, 0.1
        s.ranges = [3.0] * BEAMS
        scan_pub.publish(s)
        o = Odometry()
        o.header.stamp, o.header.frame_id, o.child_frame_id = now, "odom", "base_link"
        o.pose.pose.orientation.w = 1.0
        odom_pub.publish(o)
        if plan:
            # An L-shaped plan in the odometry frame, ending 3 m away.
            p = Path()
            p.header.stamp, p.header.frame_id = now, "odom"
            for x, y in [(0.0, 0.0), (1.5, 0.0), (1.5, 1.5), (3.0, 1.5)]:
                ps = PoseStamped()
                ps.header = p.header
                ps.pose.position.x, ps.pose.position.y = x, y
                ps.pose.orientation.w = 1.0
                p.poses.append(ps)
            plan_pub.publish(p)
        rclpy.spin_once(node, timeout_sec=0.1)
        names = node.get_node_names_and_namespaces()
        graph["node"] = graph["node"] or any(n == "rlnav_policy" and (space.rstrip("/") == ns) for n, space in names)
        for name, types in node.get_topic_names_and_types():
            if name == ns + "/cmd_vel":
                graph["cmd_vel_type"] = types
            if name == ns + "/scan":
                graph["scan_type"] = types
            if name == ns + "/plan":
                graph["plan_type"] = types
        moving = [g for g in got if g[0] > 0.05]
        if len(moving) >= 5 and graph["node"] and graph["cmd_vel_type"]:
            break
    moving = [g for g in got if g[0] > 0.05]
    ok = len(moving) >= 5 and graph["node"] and graph["cmd_vel_type"] == ["geometry_msgs/msg/Twist"]
    ok = ok and all(abs(v) <= 0.5 + 1e-6 and abs(w) <= 0.5 + 1e-6 for v, w in got)
    node.destroy_node()
    rclpy.shutdown()
    result(ok, peer="rclpy", cmd_vel=len(got), moving=len(moving), graph=graph)


def rclpy_sim(seconds):
    import rclpy
    from geometry_msgs.msg import PoseStamped, Twist
    from nav_msgs.msg import OccupancyGrid, Odometry
    from rclpy.qos import DurabilityPolicy, QoSProfile, qos_profile_sensor_data
    from sensor_msgs.msg import LaserScan

    rclpy.init()
    node = rclpy.create_node("interop_driver")
    from visualization_msgs.msg import Marker, MarkerArray

    seen = {"scan": 0, "odom": 0, "goal": 0, "beams": None, "scan_frame": None, "odom_frames": None, "map": None,
            "markers": None}
    state = {"pose": None, "goal": None}

    def on_scan(m):
        seen["scan"] += 1
        seen["beams"], seen["scan_frame"] = len(m.ranges), m.header.frame_id

    def on_odom(m):
        seen["odom"] += 1
        seen["odom_frames"] = [m.header.frame_id, m.child_frame_id]
        q = m.pose.pose.orientation
        yaw = math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))
        state["pose"] = (m.pose.pose.position.x, m.pose.pose.position.y, yaw)

    def on_goal(m):
        seen["goal"] += 1
        state["goal"] = (m.pose.position.x, m.pose.position.y)

    def on_map(m):
        data = list(m.data)
        seen["map"] = {
            "frame": m.header.frame_id, "width": m.info.width, "height": m.info.height,
            "resolution": round(m.info.resolution, 4), "cells": len(data),
            "occupied": sum(1 for v in data if v == 100), "free": sum(1 for v in data if v == 0),
        }

    def on_markers(m):
        shown = [k for k in m.markers if k.action == Marker.ADD]
        seen["markers"] = {
            "arrays": (seen["markers"] or {}).get("arrays", 0) + 1,
            "ns": {ns: sum(1 for k in shown if k.ns == ns) for ns in sorted({k.ns for k in shown})},
            "frames": sorted({k.header.frame_id for k in shown}),
            "cleared": (seen["markers"] or {}).get("cleared", False)
            or any(k.action == Marker.DELETEALL for k in m.markers),
        }

    node.create_subscription(LaserScan, "/scan", on_scan, qos_profile_sensor_data)
    node.create_subscription(MarkerArray, "/rlnav/sim/markers", on_markers, 10)
    node.create_subscription(Odometry, "/odom", on_odom, 10)
    node.create_subscription(PoseStamped, "/goal_pose", on_goal, 10)
    # As RViz2 and Nav2 subscribe to /map: transient local, so a late joiner gets it.
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    node.create_subscription(OccupancyGrid, "/map", on_map, latched)
    cmd = node.create_publisher(Twist, "/cmd_vel", 10)
    end = time.time() + seconds
    closest = math.inf
    last_count, last_change = 0, time.time()
    while time.time() < end:
        rclpy.spin_once(node, timeout_sec=0.05)
        if seen["odom"] != last_count:
            last_count, last_change = seen["odom"], time.time()
        elif last_count and time.time() - last_change > 2.0:
            break  # the bridge ended its episode
        if state["pose"] and state["goal"]:
            x, y, yaw = state["pose"]
            gx, gy = state["goal"]
            d = math.hypot(gx - x, gy - y)
            closest = min(closest, d)
            err = math.atan2(gy - y, gx - x) - yaw
            err = math.atan2(math.sin(err), math.cos(err))
            t = Twist()
            t.angular.z = max(-1.0, min(1.0, 2.0 * err))
            t.linear.x = 0.0 if abs(err) > 0.6 or d < 0.1 else min(0.3, d)
            cmd.publish(t)

    node.destroy_node()
    rclpy.shutdown()
    ok = seen["beams"] == BEAMS and seen["scan_frame"] == "laser" and seen["odom_frames"] == ["odom", "base_link"]
    # The bridge ends the episode inside its goal tolerance (0.3 m), one step before or after.
    ok = ok and closest < 0.4
    m = seen["map"]
    ok = ok and m is not None and m["frame"] == "map" and m["cells"] == m["width"] * m["height"]
    ok = ok and m["occupied"] > 0 and m["free"] > m["occupied"]
    # The scene for RViz2: the room's four walls and the goal, in the odometry frame.
    k = seen["markers"]
    ok = ok and k is not None and k["ns"].get("obstacles", 0) >= 4 and k["ns"].get("goal") == 1
    ok = ok and k["frames"] == ["odom"] and k["arrays"] > 5
    result(ok, peer="rclpy", closest=closest, **seen)


# The U of crates/cli/tests/fixtures/u-dead-end.yaml (boxes: centre, size) and a plan round it,
# from the fixed start (-2.4, 0) to the goal (2.2, 0) behind the U, as a global planner would
# route it: out to the side of the mouth, along the U's outside 0.75 m off its wall, and down to
# the goal.
U_BOXES = [((0.6, 0.0), (0.15, 1.9)), ((0.0, 0.88), (1.35, 0.15)), ((0.0, -0.88), (1.35, 0.15))]
U_ROUTE = [(-2.4, 0.0), (-1.6, 0.0), (-1.1, 1.7), (1.2, 1.7), (2.2, 0.0)]
U_GOAL_TOLERANCE = 0.3
# Inside the U: between its arms, in front of its back wall.
U_INSIDE = ((-0.675, -0.805), (0.525, 0.805))


def dense(route, step=0.05):
    """The route as poses every `step` metres, as Nav2's planners return paths (one per cell)."""
    out = [route[0]]
    for (ax, ay), (bx, by) in zip(route, route[1:]):
        n = max(1, int(math.ceil(math.hypot(bx - ax, by - ay) / step)))
        out += [(ax + (bx - ax) * k / n, ay + (by - ay) * k / n) for k in range(1, n + 1)]
    return out


def box_distance(x, y, box):
    (cx, cy), (w, h) = box
    dx, dy = max(abs(x - cx) - w / 2, 0.0), max(abs(y - cy) - h / 2, 0.0)
    return math.hypot(dx, dy)


def rclpy_u_plan(seconds, with_plan=True):
    import rclpy
    from geometry_msgs.msg import PoseStamped
    from nav_msgs.msg import Odometry, Path

    rclpy.init()
    node = rclpy.create_node("interop_planner")
    plan_pub = node.create_publisher(Path, "/plan", 10)
    state = {"odom": 0, "pose": None, "track": []}

    def on_odom(m):
        state["odom"] += 1
        p = m.pose.pose.position
        state["pose"] = (p.x, p.y)
        state["track"].append((p.x, p.y))

    node.create_subscription(Odometry, "/odom", on_odom, 10)
    points = dense(U_ROUTE)
    goal = points[-1]
    end = time.time() + seconds
    last_plan = 0.0
    arrived_after = None
    start = time.time()
    # Where along the route the robot is (a point index, only moving forward): each replan
    # starts there, as a planner's path starts at the robot.
    along = 0
    last_count, last_change = 0, time.time()
    while time.time() < end:
        rclpy.spin_once(node, timeout_sec=0.05)
        if state["odom"] != last_count:
            last_count, last_change = state["odom"], time.time()
        elif last_count and time.time() - last_change > 3.0:
            break  # the bridge ended its episode (a collision, or its time ran out)
        if with_plan and time.time() - last_plan >= 1.0:
            last_plan = time.time()
            if state["pose"]:
                x, y = state["pose"]
                window = range(along, min(len(points), along + 60))
                along = min(window, key=lambda k: math.hypot(points[k][0] - x, points[k][1] - y))
            p = Path()
            p.header.stamp, p.header.frame_id = node.get_clock().now().to_msg(), "odom"
            for x, y in points[along:]:
                ps = PoseStamped()
                ps.header = p.header
                ps.pose.position.x, ps.pose.position.y = x, y
                ps.pose.orientation.w = 1.0
                p.poses.append(ps)
            plan_pub.publish(p)
        if state["pose"] and math.hypot(state["pose"][0] - goal[0], state["pose"][1] - goal[1]) < U_GOAL_TOLERANCE:
            arrived_after = time.time() - start
            break
    node.destroy_node()
    rclpy.shutdown()
    track = state["track"]
    final = math.hypot(track[-1][0] - goal[0], track[-1][1] - goal[1]) if track else None
    closest_goal = min((math.hypot(x - goal[0], y - goal[1]) for x, y in track), default=None)
    # The robot's centre to the nearest wall of the U (the Jetbot's radius is 0.1 m).
    closest_u = min((min(box_distance(x, y, b) for b in U_BOXES) for x, y in track), default=None)
    (ax, ay), (bx, by) = U_INSIDE
    inside_u = sum(1 for x, y in track if ax < x < bx and ay < y < by)
    arrived = arrived_after is not None
    # Without a plan the run is the counterfactual: it passes when odometry was seen; the test
    # reads `arrived`.
    ok = state["odom"] > 10 and (arrived or not with_plan)
    result(ok, peer="rclpy", plan=with_plan, arrived=arrived, seconds=arrived_after, final_distance=final,
           closest_to_goal=closest_goal, closest_to_u=closest_u, inside_u=inside_u, odom=state["odom"],
           plan_poses=len(points),
           end=track[-1] if track else None)


# ---------------------------------------------------------------- Eclipse Cyclone DDS

CYCLONE_LOOPBACK = """<CycloneDDS><Domain id="any"><General><Interfaces>
<NetworkInterface address="127.0.0.1"/></Interfaces><AllowMulticast>false</AllowMulticast></General>
<Discovery><ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>30</MaxAutoParticipantIndex>
<Peers><Peer address="127.0.0.1"/></Peers></Discovery></Domain></CycloneDDS>"""


def cyclone_types():
    """The ROS 2 messages as Cyclone IDL structs, with ROS 2's DDS type names."""
    from dataclasses import dataclass, field

    import cyclonedds.idl.annotations as annotate
    from cyclonedds.idl import IdlStruct
    from cyclonedds.idl.types import array, float32, float64, int32, sequence, uint32

    @dataclass
    @annotate.final
    class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
        sec: int32 = 0
        nanosec: uint32 = 0

    @dataclass
    @annotate.final
    class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
        stamp: Time = field(default_factory=Time)
        frame_id: str = ""

    @dataclass
    @annotate.final
    class Vector3(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
        x: float64 = 0.0
        y: float64 = 0.0
        z: float64 = 0.0

    @dataclass
    @annotate.final
    class Point(IdlStruct, typename="geometry_msgs::msg::dds_::Point_"):
        x: float64 = 0.0
        y: float64 = 0.0
        z: float64 = 0.0

    @dataclass
    @annotate.final
    class Quaternion(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
        x: float64 = 0.0
        y: float64 = 0.0
        z: float64 = 0.0
        w: float64 = 1.0

    @dataclass
    @annotate.final
    class Pose(IdlStruct, typename="geometry_msgs::msg::dds_::Pose_"):
        position: Point = field(default_factory=Point)
        orientation: Quaternion = field(default_factory=Quaternion)

    @dataclass
    @annotate.final
    class PoseWithCovariance(IdlStruct, typename="geometry_msgs::msg::dds_::PoseWithCovariance_"):
        pose: Pose = field(default_factory=Pose)
        covariance: array[float64, 36] = field(default_factory=lambda: [0.0] * 36)

    @dataclass
    @annotate.final
    class Twist(IdlStruct, typename="geometry_msgs::msg::dds_::Twist_"):
        linear: Vector3 = field(default_factory=Vector3)
        angular: Vector3 = field(default_factory=Vector3)

    @dataclass
    @annotate.final
    class TwistWithCovariance(IdlStruct, typename="geometry_msgs::msg::dds_::TwistWithCovariance_"):
        twist: Twist = field(default_factory=Twist)
        covariance: array[float64, 36] = field(default_factory=lambda: [0.0] * 36)

    @dataclass
    @annotate.final
    class Odometry(IdlStruct, typename="nav_msgs::msg::dds_::Odometry_"):
        header: Header = field(default_factory=Header)
        child_frame_id: str = ""
        pose: PoseWithCovariance = field(default_factory=PoseWithCovariance)
        twist: TwistWithCovariance = field(default_factory=TwistWithCovariance)

    @dataclass
    @annotate.final
    class LaserScan(IdlStruct, typename="sensor_msgs::msg::dds_::LaserScan_"):
        header: Header = field(default_factory=Header)
        angle_min: float32 = 0.0
        angle_max: float32 = 0.0
        angle_increment: float32 = 0.0
        time_increment: float32 = 0.0
        scan_time: float32 = 0.0
        range_min: float32 = 0.0
        range_max: float32 = 0.0
        ranges: sequence[float32] = field(default_factory=list)
        intensities: sequence[float32] = field(default_factory=list)

    return LaserScan, Odometry, Twist, Header


def cyclone_participant():
    os.environ.setdefault("CYCLONEDDS_URI", CYCLONE_LOOPBACK)
    from cyclonedds.domain import DomainParticipant

    return DomainParticipant(int(os.environ.get("ROS_DOMAIN_ID", "0")))


def cyclone_qos(reliable, depth):
    from cyclonedds.core import Policy, Qos
    from cyclonedds.util import duration

    rel = Policy.Reliability.Reliable(duration(milliseconds=100)) if reliable else Policy.Reliability.BestEffort
    # Plain CDR (XCDR1), as ROS 2 sends.
    return Qos(rel, Policy.History.KeepLast(depth), Policy.Durability.Volatile,
               Policy.DataRepresentation(use_cdrv0_representation=True))


def cyclone_node(seconds):
    from cyclonedds.pub import DataWriter
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic

    LaserScan, Odometry, Twist, Header = cyclone_types()
    dp = cyclone_participant()
    scan_w = DataWriter(dp, Topic(dp, "rt/scan", LaserScan), qos=cyclone_qos(False, 5))
    odom_w = DataWriter(dp, Topic(dp, "rt/odom", Odometry), qos=cyclone_qos(True, 10))
    cmd_r = DataReader(dp, Topic(dp, "rt/cmd_vel", Twist), qos=cyclone_qos(True, 10))
    got = []
    end = time.time() + seconds
    inc = 2 * math.pi / BEAMS
    while time.time() < end:
        scan_w.write(LaserScan(header=Header(frame_id="laser"), angle_min=-math.pi, angle_max=-math.pi + inc * (BEAMS - 1),
                               angle_increment=inc, scan_time=0.1, range_min=0.05, range_max=8.0, ranges=[3.0] * BEAMS))
        odom_w.write(Odometry(header=Header(frame_id="odom"), child_frame_id="base_link"))
        for m in cmd_r.take(N=100):
            got.append((m.linear.x, m.angular.z))
        if len([g for g in got if g[0] > 0.05]) >= 5:
            break
        time.sleep(0.1)
    moving = [g for g in got if g[0] > 0.05]
    ok = len(moving) >= 5 and all(abs(v) <= 0.5 + 1e-6 and abs(w) <= 0.5 + 1e-6 for v, w in got)
    result(ok, peer="cyclonedds", cmd_vel=len(got), moving=len(moving))


def cyclone_sim(seconds):
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic

    LaserScan, Odometry, Twist, Header = cyclone_types()
    dp = cyclone_participant()
    scan_r = DataReader(dp, Topic(dp, "rt/scan", LaserScan), qos=cyclone_qos(False, 5))
    odom_r = DataReader(dp, Topic(dp, "rt/odom", Odometry), qos=cyclone_qos(True, 10))
    seen = {"scan": 0, "odom": 0, "beams": None, "scan_frame": None, "odom_frames": None, "range_max": None}
    end = time.time() + seconds
    while time.time() < end and (seen["scan"] < 3 or seen["odom"] < 3):
        for m in scan_r.take(N=100):
            seen["scan"] += 1
            seen["beams"], seen["scan_frame"], seen["range_max"] = len(m.ranges), m.header.frame_id, m.range_max
        for m in odom_r.take(N=100):
            seen["odom"] += 1
            seen["odom_frames"] = [m.header.frame_id, m.child_frame_id]
        time.sleep(0.05)
    ok = seen["scan"] >= 3 and seen["odom"] >= 3 and seen["beams"] == BEAMS and seen["scan_frame"] == "laser"
    ok = ok and seen["odom_frames"] == ["odom", "base_link"]
    result(ok, peer="cyclonedds", **seen)


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("mode", choices=["rclpy-node", "rclpy-plan", "rclpy-u-plan", "rclpy-sim", "cyclone-node",
                                     "cyclone-sim"])
    ap.add_argument("--seconds", type=float, default=30.0)
    ap.add_argument("--ns", default="", help="the rlnav node's namespace (rclpy-node), e.g. /robot1")
    ap.add_argument("--no-plan", action="store_true", help="rclpy-u-plan: publish no plan (the counterfactual)")
    a = ap.parse_args()
    {"rclpy-node": lambda t: rclpy_node(t, ns=a.ns), "rclpy-sim": rclpy_sim, "cyclone-node": cyclone_node,
     "cyclone-sim": cyclone_sim, "rclpy-plan": lambda t: rclpy_node(t, plan=True),
     "rclpy-u-plan": lambda t: rclpy_u_plan(t, with_plan=not a.no_plan)}[a.mode](a.seconds)
