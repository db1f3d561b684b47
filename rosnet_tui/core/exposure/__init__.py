"""What is exposed to the internet: the firewall, the ports to forward, the router card, and
the outsider's view."""
