#!/usr/bin/python3
"""A minimal ROS 1 talker for the lab: publishes "hello from <hostname> <n>" on a topic.

    /usr/bin/python3 talker.py [TOPIC] [RATE_HZ]
"""

import socket
import sys

import rospy
from std_msgs.msg import String


def main() -> None:
    topic = sys.argv[1] if len(sys.argv) > 1 else "/rnl_chatter"
    rate_hz = float(sys.argv[2]) if len(sys.argv) > 2 else 5.0
    rospy.init_node("rnl_talker", anonymous=True, disable_signals=False)
    pub = rospy.Publisher(topic, String, queue_size=10)
    print(f"talker on {topic} as {rospy.get_name()} at {rospy.get_node_uri()}", flush=True)
    rate = rospy.Rate(rate_hz)
    n = 0
    while not rospy.is_shutdown():
        pub.publish(String(data=f"hello from {socket.gethostname()} {n}"))
        n += 1
        try:
            rate.sleep()
        except rospy.ROSInterruptException:
            break


if __name__ == "__main__":
    main()
