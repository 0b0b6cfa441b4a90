"""The wall-inspector command line."""
