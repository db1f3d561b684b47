"""The Textual wizard. Everything it decides comes from rosnet_tui.core."""
