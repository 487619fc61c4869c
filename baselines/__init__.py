"""Reference and baseline trackers."""
