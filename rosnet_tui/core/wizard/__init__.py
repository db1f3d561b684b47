"""The wizard itself: the session the UI and CLI drive, its steps, the write plans, the report."""
