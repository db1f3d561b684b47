"""The vocabulary the declarations of several steps share."""

from __future__ import annotations

from typing import Literal

# How a TCP connection attempt went (rosnet_tui/core/net/connect.py): "connected"; "refused" (something
# at the address answered with a reset: online, rejecting the port); "timeout" (nothing answered:
# dropped); "unreachable" (an ICMP error: no route, or no machine where a modem forwards to);
# "error" (anything else).
TcpKind = Literal["connected", "refused", "timeout", "unreachable", "error"]
