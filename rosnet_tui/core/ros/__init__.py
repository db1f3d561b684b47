"""ROS: rosbridge, ROS 2 over rmw_zenoh (its config), and the fleet's TLS and pairing."""
