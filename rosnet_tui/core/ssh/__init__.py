"""SSH to peers by name, host keys verified, keys only, everything bounded.

- :mod:`.options`: what the layer is told (:class:`~.options.SshOptions`), where keys live;
- :mod:`.known_hosts`: reading known_hosts, adding a confirmed key, how to verify one by hand;
- :mod:`.connection`: resolving, connecting and logging in, failures as classified results;
- :mod:`.session`: a command on the peer (:func:`~.session.ssh_run`, :func:`~.session.ssh_session`);
- :mod:`.pool`: one connection per peer shared by a round's checks.

Import from the module that defines a name; this face gathers none.
"""
