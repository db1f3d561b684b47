#!/usr/bin/python3
"""A minimal ROS 1 listener for the lab: prints "heard: <data>" for every message on a topic.

    /usr/bin/python3 listener.py [TOPIC]
"""

import sys

import rospy
from std_msgs.msg import String


def main() -> None:
    topic = sys.argv[1] if len(sys.argv) > 1 else "/rnl_chatter"
    rospy.init_node("rnl_listener", anonymous=True)
    rospy.Subscriber(topic, String, lambda msg: print(f"heard: {msg.data}", flush=True))
    print(f"listener on {topic} as {rospy.get_name()} at {rospy.get_node_uri()}", flush=True)
    rospy.spin()


if __name__ == "__main__":
    main()
