"""What the checks of several steps share, one module a topic: time budgets (budget), HTTP
to the configured services (http), the public IP (public_ip), the peers and working with them
concurrently (peers), the round's peer agents (agents), and what the ROS 2 checks share (ros2).

The check modules import from here and from the core, never from each other, so each step's
checks can change without opening another step's file. The shell commands that start a program
on a peer are core/peer/commands.py's (pairing uses them too).
"""
