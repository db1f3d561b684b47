"""rosnet-tui's own saved files: the settings file, the state file and the UI's memory."""
