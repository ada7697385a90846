"""Serialize reference messages with a real ROS 2 (rclpy for Jazzy, Fast DDS's CDR) and print
them as JSON {type: hex}. rlnav's message structs must produce the same bytes:
crates/ros2/tests/fixtures/cdr_golden.json is this script's output, and
crates/ros2/tests/cdr.rs builds the same messages in Rust and compares.

    python3.12 -m venv venv && venv/bin/pip install ros-jazzy-rclpy ros-jazzy-sensor-msgs \
        ros-jazzy-nav-msgs ros-jazzy-geometry-msgs ros-jazzy-rosgraph-msgs ros-jazzy-rmw-fastrtps-cpp \
        ros-jazzy-visualization-msgs
    venv/bin/python tools/ros2_golden.py > crates/ros2/tests/fixtures/cdr_golden.json
"""
import json
import math

from rclpy.serialization import serialize_message
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped, TransformStamped, Twist, TwistStamped
from nav_msgs.msg import Odometry
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import LaserScan
from std_msgs.msg import String

# tf2_msgs is not on PyPI, so TFMessage (a TransformStamped[]) is checked through the MCAP
# reader test instead (tools/mcap_check.py decodes it with mcap-ros2-support).
# The values are repeated literally in crates/ros2/tests/cdr.rs.
QZ, QW = 0.24740395925452294, 0.9689124217106447


def stamp(sec, nanosec):
    return Time(sec=sec, nanosec=nanosec)


def scan():
    m = LaserScan()
    m.header.stamp = stamp(12, 345)
    m.header.frame_id = "laser"
    m.angle_min, m.angle_max, m.angle_increment = -3.1415927, 3.1241393, 0.017453292
    m.time_increment, m.scan_time = 0.0, 0.1
    m.range_min, m.range_max = 0.12, 3.5
    m.ranges = [1.0, math.inf, 0.5]
    m.intensities = []
    return m


def odom():
    m = Odometry()
    m.header.stamp = stamp(3, 500000000)
    m.header.frame_id = "odom"
    m.child_frame_id = "base_link"
    m.pose.pose.position.x, m.pose.pose.position.y = 1.5, -2.25
    m.pose.pose.orientation.z, m.pose.pose.orientation.w = QZ, QW
    cov = [0.0] * 36
    cov[0], cov[35] = 0.01, 0.05
    m.pose.covariance = cov
    m.twist.twist.linear.x, m.twist.twist.angular.z = 0.3, -0.4
    tcov = [0.0] * 36
    tcov[7] = 0.02
    m.twist.covariance = tcov
    return m


def twist():
    m = Twist()
    m.linear.x, m.angular.z = 0.3, -0.4
    return m


def twist_stamped():
    m = TwistStamped()
    m.header.stamp = stamp(7, 1)
    m.header.frame_id = "base_link"
    m.twist = twist()
    return m


def pose_stamped():
    m = PoseStamped()
    m.header.stamp = stamp(0, 0)
    m.header.frame_id = "map"
    m.pose.position.x, m.pose.position.y = 4.0, 0.5
    m.pose.orientation.z, m.pose.orientation.w = QZ, QW
    return m


def marker_array():
    from geometry_msgs.msg import Point
    from std_msgs.msg import ColorRGBA
    from visualization_msgs.msg import Marker, MarkerArray

    clear = Marker(action=Marker.DELETEALL)
    box = Marker(ns="movers", id=3, type=Marker.CUBE, action=Marker.ADD)
    box.header.stamp, box.header.frame_id = stamp(7, 250), "odom"
    box.pose.position.x, box.pose.position.y, box.pose.position.z = 1.5, -2.0, 0.25
    box.pose.orientation.z, box.pose.orientation.w = QZ, QW
    box.scale.x, box.scale.y, box.scale.z = 0.6, 0.4, 0.5
    box.color = ColorRGBA(r=0.95, g=0.5, b=0.1, a=1.0)
    tri = Marker(ns="obstacles", id=12, type=Marker.TRIANGLE_LIST, frame_locked=True, text="wedge")
    tri.header.frame_id = "odom"
    tri.pose.orientation.w = 1.0
    tri.scale.x = tri.scale.y = tri.scale.z = 1.0
    tri.points = [Point(x=0.0, y=0.0, z=0.0), Point(x=1.0, y=0.0, z=0.0), Point(x=0.0, y=2.0, z=0.0)]
    tri.lifetime.sec, tri.lifetime.nanosec = 2, 500
    return MarkerArray(markers=[clear, box, tri])


def path():
    from nav_msgs.msg import Path

    m = Path()
    m.header.stamp = stamp(5, 25)
    m.header.frame_id = "map"
    for x, y in [(0.0, 0.0), (1.0, 0.5)]:
        p = pose_stamped()
        p.header.stamp = m.header.stamp
        p.pose.position.x, p.pose.position.y = x, y
        m.poses.append(p)
    return m


def empty():
    from std_msgs.msg import Empty

    return Empty()


messages = {
    "sensor_msgs/msg/LaserScan": scan(),
    "nav_msgs/msg/Odometry": odom(),
    "geometry_msgs/msg/Twist": twist(),
    "geometry_msgs/msg/TwistStamped": twist_stamped(),
    "geometry_msgs/msg/PoseStamped": pose_stamped(),
    "rosgraph_msgs/msg/Clock": Clock(clock=stamp(42, 999999999)),
    "std_msgs/msg/String": String(data="driving"),
    "visualization_msgs/msg/MarkerArray": marker_array(),
    # The plan's type, and the one-byte empty structure inside FollowPath's result.
    "nav_msgs/msg/Path": path(),
    "std_msgs/msg/Empty": empty(),
}
print(json.dumps({k: serialize_message(v).hex() for k, v in messages.items()}, indent=1))
