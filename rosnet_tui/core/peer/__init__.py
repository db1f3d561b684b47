"""The programs fed to peers over SSH (stdlib only, run by path-less ``python3 -S``), and the
master's side that starts and talks to them."""
