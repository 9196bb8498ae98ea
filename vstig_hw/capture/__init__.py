"""Captures: timestamped link units to and from files."""
