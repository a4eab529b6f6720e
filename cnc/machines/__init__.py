"""Shipped default machines (YAML machine sections); see cnc.config and docs/configuration.md."""
