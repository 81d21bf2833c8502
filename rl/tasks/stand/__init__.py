"""The stand task."""
