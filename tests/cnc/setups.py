"""Machines for tests whose programs are written in machine coordinates: the shipped
machine with `machine_data: null` (G54 = 0, no tools) instead of its factory setup."""

from __future__ import annotations

from cnc.config import load_machine_config


def machine_coordinates(name: str = "mill3", **over):
    """The shipped machine `name` with every work offset 0 and an empty tool table."""
    return load_machine_config({"base": name, "machine_data": None, **over})
