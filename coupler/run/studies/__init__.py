"""Scenes run inside the coupler process (plates, obstacle, closure, transfer)."""
