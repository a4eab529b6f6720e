"""A whole cell with `host.mqtt` on the real broker: its machines' live state and its
outbox's events, as a factory sees them."""

from __future__ import annotations

import uuid

import pytest

from server.config import load_cell_config
from tests.cell.conftest import idem, upload_released
from tests.server.mqtt_support import Subscriber, broker_answers, clear_retained

pytestmark = pytest.mark.skipif(
    not broker_answers(), reason="no MQTT broker answers on 127.0.0.1:1883 (.ci/run starts one)"
)


def test_a_dispatched_part_shows_on_the_broker_with_its_events(make_cell):
    prefix = f"test-{uuid.uuid4().hex[:12]}"
    config = load_cell_config(
        {
            "machines": {
                "mill1": {"base": "mill3", "ports": {"dnc": 0, "modbus": 0, "shdr": 0}},
            },
            "host": {"mqtt": {"broker": "127.0.0.1:1883", "prefix": prefix, "cell_id": "e2e"}},
        }
    )
    root = f"{prefix}/e2e"
    sub = Subscriber("127.0.0.1", 1883, [f"{root}/#"])
    try:
        assert sub.subscribed.wait(10)
        cell, api = make_cell(config=config)
        sub.wait_for(
            lambda ms: (
                (sub.last(f"{root}/status") or {}).get("status") == "ONLINE"
                and (sub.last(f"{root}/mill1/execution") or {}).get("value") == "READY"
                # each data item is its own message: mode may follow execution on the wire
                and (sub.last(f"{root}/mill1/mode") or {}).get("value") == "AUTOMATIC"
            ),
            30,
            what="the cell's birth and mill1 READY in AUTOMATIC",
        )

        rev = upload_released(api)
        r = api("operator").post(
            "/api/dispatches",
            json={"revision_id": rev, "machine": "mill1", "mode": "memory", "start": True},
            headers=idem(),
        )
        assert r.status_code == 202, r.text
        sub.wait_for(
            lambda ms: (sub.last(f"{root}/mill1/part_count") or {}).get("value") == 1,
            60,
            what="mill1's part count 1",
        )
        values = [b["value"] for t, b, _ in sub.messages if t == f"{root}/mill1/execution"]
        assert "ACTIVE" in values
        assert sub.last(f"{root}/mill1/program")["value"] == "O1001"
        wanted = {f"{root}/events/dispatch/done", f"{root}/events/machine/cycle_start"}
        sub.wait_for(lambda ms: wanted <= {t for t, _, _ in ms}, 30, what="the dispatch's events")
        events = [(t, b) for t, b, _ in sub.messages if t.startswith(f"{root}/events/")]
        ids = [b["event_id"] for _, b in events]
        assert ids == sorted(ids) and len(set(ids)) == len(ids)
        assert f"{root}/events/program/create" in [t for t, _ in events]

        cell.stop()
        sub.wait_for(
            lambda ms: sub.last(f"{root}/status")["status"] == "OFFLINE", 10, what="OFFLINE"
        )
    finally:
        sub.close()
        clear_retained("127.0.0.1", 1883, prefix)
