"""The controller's alarm list as OPC UA Alarms & Conditions (AlarmConditionType) events.

One condition per alarm of the list, named by its native code (the same number the REST API
and MTConnect show as `code` / nativeCode) and carrying the same text. Raised: an event with
ActiveState true, AckedState false, Retain true. Gone from the list (the machine was reset):
ActiveState false; it stays retained until acknowledged. Acknowledge (the standard method,
operator and above) sets AckedState; an acknowledged, inactive condition is no longer
retained. Events are emitted from the machine's Notification/Messages node and from the
Server object (clients subscribe to either).
"""

from __future__ import annotations

import datetime as _dt
from collections.abc import Callable
from dataclasses import dataclass

from asyncua import Server, ua

from cnc.faces.opcua.space import Space
from cnc.status import Alarm

SEVERITY = {"FAULT": 800, "WARNING": 400}


@dataclass
class Condition:
    key: tuple
    alarm: Alarm
    node: ua.NodeId
    active: bool = True
    acked: bool = False
    event_ids: tuple[bytes, ...] = ()  # of the last emission (one per emitting node)


class AlarmBook:
    def __init__(
        self,
        server: Server,
        space: Space,
        machine: str,
        record: Callable[[str, int, str], ua.StatusCode] | None = None,
    ) -> None:
        """`record(command, status code, detail)`: each Acknowledge call, for the audit."""
        self.server, self.space, self.machine = server, space, machine
        self._record = record or (lambda command, code, detail="": ua.StatusCode(code))
        self.conditions: dict[tuple, Condition] = {}
        self._generators = []

    async def start(self) -> None:
        messages = ua.NodeId(f"{self.machine}.Notification.Messages", self.space.machine_ns)
        for emitter in (messages, ua.NodeId(ua.ObjectIds.Server)):
            self._generators.append(
                await self.server.get_event_generator(ua.ObjectIds.AlarmConditionType, emitter)
            )
        self.server.link_method(
            self.server.get_node(ua.NodeId(ua.ObjectIds.AcknowledgeableConditionType_Acknowledge)),
            self._acknowledge,
        )

    async def update(self, alarms: tuple[Alarm, ...], when: _dt.datetime) -> None:
        present = {}
        for alarm in alarms:
            present[(alarm.source, alarm.number, alarm.axis)] = alarm
        for key, alarm in present.items():
            cond = self.conditions.get(key)
            if cond is None or not cond.active:
                node = ua.NodeId(
                    f"{self.machine}.Alarm.{alarm.source}.{alarm.number}"
                    + (f".{alarm.axis}" if alarm.axis else ""),
                    self.space.machine_ns,
                )
                cond = Condition(key, alarm, node)
                self._add_condition_node(cond)
                self.conditions[key] = cond
                await self._emit(cond, when)
        for key, cond in list(self.conditions.items()):
            if key not in present and cond.active:
                cond.active = False  # cleared: the machine was reset
                await self._emit(cond, when)
                if cond.acked:
                    await self._forget(key)

    def _add_condition_node(self, cond: Condition) -> None:
        """The condition's node (its ConditionId; Acknowledge is called on it), referenced
        from Messages with HasCondition, as Part 9 shows condition instances."""
        if cond.node in self.server.iserver.aspace:
            return  # raised again while still retained
        item = ua.AddNodesItem()
        item.RequestedNewNodeId = cond.node
        item.BrowseName = ua.QualifiedName(cond.node.Identifier, self.space.machine_ns)
        item.NodeClass = ua.NodeClass.Object
        item.ParentNodeId = ua.NodeId(
            f"{self.machine}.Notification.Messages", self.space.machine_ns
        )
        item.ReferenceTypeId = ua.NodeId(ua.ObjectIds.HasCondition)
        item.TypeDefinition = ua.NodeId(ua.ObjectIds.AlarmConditionType)
        attrs = ua.ObjectAttributes()
        attrs.DisplayName = ua.LocalizedText(f"{cond.alarm.source} {cond.alarm.number}")
        item.NodeAttributes = attrs
        self.server.iserver.node_mgt_service.add_nodes([item])[0].StatusCode.check()

    async def _forget(self, key: tuple) -> None:
        cond = self.conditions.pop(key)
        if any(c.node == cond.node for c in self.conditions.values()):
            return
        await self.server.delete_nodes([self.server.get_node(cond.node)], recursive=True)

    async def _emit(self, cond: Condition, when: _dt.datetime) -> None:
        ids = []
        alarm = cond.alarm
        retain = cond.active or not cond.acked
        for gen in self._generators:
            ev = gen.event
            ev.NodeId = cond.node  # the ConditionId
            ev.SourceNode = self.space.root
            ev.SourceName = f"{self.machine}/{alarm.source}" + (
                f"/{alarm.axis}" if alarm.axis else ""
            )
            ev.ConditionName = str(alarm.number)
            ev.Message = ua.LocalizedText(alarm.text)
            ev.Severity = SEVERITY.get(alarm.severity, 500)
            ev.Retain = retain
            ev.Time = when
            ev.ActiveState = ua.LocalizedText("Active" if cond.active else "Inactive")
            setattr(ev, "ActiveState/Id", cond.active)
            ev.AckedState = ua.LocalizedText("Acknowledged" if cond.acked else "Unacknowledged")
            setattr(ev, "AckedState/Id", cond.acked)
            ev.EnabledState = ua.LocalizedText("Enabled")
            setattr(ev, "EnabledState/Id", True)
            await gen.trigger(time_attr=when)
            ids.append(_bytes(ev.EventId))
        cond.event_ids = tuple(ids)

    async def _acknowledge(self, parent: ua.NodeId, event_id: ua.Variant, comment: ua.Variant):
        """Acknowledge(EventId, Comment) called on a condition (its ConditionId)."""
        eid = event_id.Value if isinstance(event_id, ua.Variant) else event_id
        for key, cond in list(self.conditions.items()):
            if cond.node == parent or eid in cond.event_ids:
                what = f"alarm {cond.alarm.number} ({cond.alarm.source})"
                if eid not in cond.event_ids:
                    return self._record("acknowledge", ua.StatusCodes.BadEventIdUnknown, what)
                if cond.acked:
                    return self._record(
                        "acknowledge", ua.StatusCodes.BadConditionBranchAlreadyAcked, what
                    )
                cond.acked = True
                self._record("acknowledge", ua.StatusCodes.Good, what)
                await self._emit(cond, _dt.datetime.now(_dt.UTC))
                if not cond.active:
                    await self._forget(key)
                return []
        return self._record("acknowledge", ua.StatusCodes.BadEventIdUnknown, str(parent))


def _bytes(value) -> bytes:
    value = value.Value if isinstance(value, ua.Variant) else value
    return value if isinstance(value, bytes) else bytes(value or b"")
