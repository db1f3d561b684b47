"""rosnet_tui: put a robot and its operators on one ROS network across the internet."""

__version__ = "0.1.0"
