"""Scenes run inside the coupler process (obstacle, closure)."""
