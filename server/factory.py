"""The factory view: every cell and machine a broker has heard of, from the cells' retained
MQTT topics (`fmscell factory --mqtt HOST:PORT`, docs/mqtt.md)."""

from __future__ import annotations

import json
import threading
import time
import uuid

import typer

from server.mqtt import RESERVED, parse_broker

# the columns of the table, in order
COLUMNS = ("availability", "state", "mode", "execution", "program", "line", "part_count")


class FactoryView:
    """Subscribes to `<prefix>/+/status` and `<prefix>/+/+/+` and keeps what it hears."""

    def __init__(self, host: str, port: int, prefix: str = "fmscell") -> None:
        self.host, self.port, self.prefix = host, port, prefix.strip("/")
        self.cells: dict[str, dict] = {}
        self.errors: list[str] = []
        self._lock = threading.Lock()
        self.subscribed = threading.Event()

    def collect(self, seconds: float) -> dict[str, dict]:
        """Listen for `seconds` after subscribing (retained values come first) and return
        the cells; a broker that does not answer raises ConnectionError."""
        import paho.mqtt.client as mqtt

        client = mqtt.Client(
            mqtt.CallbackAPIVersion.VERSION2, client_id=f"fmscell-factory-{uuid.uuid4().hex[:8]}"
        )
        client.on_connect = lambda c, *_: c.subscribe(
            [(f"{self.prefix}/+/status", 1), (f"{self.prefix}/+/+/+", 1)]
        )
        client.on_subscribe = lambda *_: self.subscribed.set()
        client.on_message = lambda c, u, msg: self.hear(msg.topic, msg.payload)
        try:
            client.connect(self.host, self.port, keepalive=10)
        except OSError as exc:
            raise ConnectionError(f"MQTT broker {self.host}:{self.port}: {exc}") from None
        client.loop_start()
        try:
            if not self.subscribed.wait(max(seconds, 5.0)):
                raise ConnectionError(f"MQTT broker {self.host}:{self.port} did not answer")
            time.sleep(seconds)  # a listening window, not a wait for a simulation
        finally:
            client.disconnect()
            client.loop_stop()
        return self.snapshot()

    def hear(self, topic: str, payload: bytes) -> None:
        """One message: a cell's status or one machine item."""
        levels = topic[len(self.prefix) + 1 :].split("/")
        if not payload:
            return  # a cleared retained topic
        try:
            body = json.loads(payload)
        except ValueError:
            self.errors.append(f"{topic}: payload is not JSON")
            return
        if not isinstance(body, dict):
            self.errors.append(f"{topic}: payload is not a JSON object")
            return
        with self._lock:
            cell = self.cells.setdefault(levels[0], {"status": "UNKNOWN", "machines": {}})
            if levels[1:] == ["status"]:
                cell["status"] = body.get("status", "UNKNOWN")
                cell["since"] = body.get("timestamp")
                for name in body.get("machines") or ():
                    cell["machines"].setdefault(name, {})
            elif len(levels) == 3 and levels[1] not in RESERVED:
                cell["machines"].setdefault(levels[1], {})[levels[2]] = body.get("value")

    def snapshot(self) -> dict[str, dict]:
        """The cells heard; a machine of a cell that is not ONLINE reads UNAVAILABLE (its
        retained values are the last its cell knew)."""
        with self._lock:
            out = {}
            for name, cell in sorted(self.cells.items()):
                machines = {}
                for m, items in sorted(cell["machines"].items()):
                    items = dict(items)
                    if cell["status"] != "ONLINE":
                        items["availability"] = "UNAVAILABLE"
                    machines[m] = items
                out[name] = {**cell, "machines": machines}
            return out


def table(cells: dict[str, dict]) -> str:
    rows = [("cell", "status", "machine", *COLUMNS)]
    for cell_name, cell in cells.items():
        rows.append((cell_name, cell["status"], "", *[""] * len(COLUMNS)))
        for m, items in cell["machines"].items():
            rows.append(("", "", m, *(_cell_text(items.get(c)) for c in COLUMNS)))
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    return "\n".join(
        "  ".join(v.ljust(w) for v, w in zip(r, widths, strict=True)).rstrip() for r in rows
    )


def _cell_text(value) -> str:
    return "-" if value is None else str(value)


def factory(
    mqtt: str = typer.Option(..., "--mqtt", help="the broker, HOST:PORT"),
    prefix: str = typer.Option("fmscell", "--prefix", help="the cells' topic prefix"),
    seconds: float = typer.Option(2.0, "--seconds", min=0.0, help="how long to listen"),
    as_json: bool = typer.Option(False, "--json", help="one JSON object instead of a table"),
) -> None:
    """List every cell and machine publishing to an MQTT broker, with their state."""
    try:
        host, port = parse_broker(mqtt, "--mqtt")
        view = FactoryView(host, port, prefix)
        cells = view.collect(seconds)
    except (ValueError, ConnectionError) as exc:
        typer.echo(f"fmscell factory: {exc}", err=True)
        raise typer.Exit(2) from None
    if as_json:
        doc = {"broker": f"{host}:{port}", "prefix": prefix, "cells": cells, "errors": view.errors}
        typer.echo(json.dumps(doc))
        return
    for error in view.errors:  # a message under the prefix that no cell of ours wrote
        typer.echo(f"fmscell factory: {error}", err=True)
    if cells:
        typer.echo(table(cells))
    else:
        typer.echo(f"no cell heard on {host}:{port} under {prefix}/ in {seconds:g} s")
