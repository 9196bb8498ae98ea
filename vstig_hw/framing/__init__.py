"""Framings: each turns one kind of link unit into Messages and back."""
