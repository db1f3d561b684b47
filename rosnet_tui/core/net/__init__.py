"""Network primitives: TCP connects, listeners, local interfaces and networks, the probe server."""
