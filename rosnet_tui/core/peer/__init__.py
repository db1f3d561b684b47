"""The programs fed to peers over SSH (stdlib only, run by path-less ``python3 -S``; the Zenoh
program and the SSH audit's sshnone run on the peer's rosnet-tui install), and the master's side
that starts and talks to them."""
