"""What the settings are (the model, its checks and defaults) and where rosnet-tui's files are."""
