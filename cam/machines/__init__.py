"""Shipped machine descriptions for the posts (cam.machine5, docs/cam.md)."""
