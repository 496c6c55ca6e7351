"""Shipped chain files (YAML)."""
