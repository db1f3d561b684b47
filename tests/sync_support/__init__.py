"""Helpers for the sync tests and the benchmark: the sync service on the network lab, an
authoritative BIND server for the DNS store, the change-to-update latency measurement."""
