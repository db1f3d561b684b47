"""The writers of files we share with the system and the user (/etc/hosts, ~/.bashrc), atomic and
in marked blocks, with their undo journal, the torn-write journal and root's door (privilege)."""
