"""The MachineTool instance under Objects/Machines, group by group, built with the
`Builder`'s helpers (space.py): the fixed tree at start, then the groups that come and go
with the machine's data (a ProductionJob per host job, a Tool per tool offset).

Each function names the browse names and types of OPC 40501-1 it fills; docs/opcua.md
draws the resulting tree.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

from asyncua import ua

from cnc.faces.opcua import model as m
from cnc.faces.opcua.host_data import ProductionJob
from cnc.faces.opcua.space import HOUR, ONE, Builder
from cnc.faces.opcua.values import STACK_LAMPS, color, current_state

MT, FMS = m.MACHINE_TOOL, m.FMSCELL


@dataclass(frozen=True)
class Identification:
    manufacturer: str = "fmscell"
    model: str = ""
    serial_number: str = ""
    software_revision: str = ""
    location: str = ""


def machine_tool(
    b: Builder,
    name: str,
    ident: Identification,
    axes: tuple[str, ...],
    methods: Mapping[str, Callable],
) -> ua.NodeId:
    """The fixed tree; `methods`: the Channel's vendor methods by browse name."""
    sp = b.space
    machines = sp.node(m.MACHINES_FOLDER)
    b.object(
        ua.NodeId(ua.ObjectIds.ObjectsFolder),
        machines,
        ua.QualifiedName("Machines", sp.ns[m.MACHINERY]),
        ua.NodeId(ua.ObjectIds.FolderType),
        ref=ua.ObjectIds.Organizes,
    )
    root = b.child_object(
        machines,
        name,
        (FMS, name),
        m.MACHINE_TOOL_TYPE.node,
        ref=ua.ObjectIds.Organizes,
        notifier=True,
    )
    sp.root = root
    _identification(b, root, name, ident)
    mon = b.child_object(root, f"{name}.Monitoring", (MT, "Monitoring"), m.MONITORING.node)
    _operation(b, mon, f"{name}.Monitoring.MachineTool")
    _channel(b, mon, f"{name}.Monitoring.Channel1", axes, methods)
    _spindle(b, mon, f"{name}.Monitoring.Spindle")
    _stacklight(b, mon, f"{name}.Monitoring.Stacklight")
    prod = b.child_object(root, f"{name}.Production", (MT, "Production"), m.PRODUCTION.node)
    _active_program(b, prod, f"{name}.Production.ActiveProgram")
    b.child_object(
        prod,
        f"{name}.Production.ProductionPlan",
        (MT, "ProductionPlan"),
        m.PRODUCTION_JOB_LIST.node,
    )
    note = b.child_object(
        root, f"{name}.Notification", (MT, "Notification"), m.NOTIFICATION.node, notifier=True
    )
    b.child_object(
        note, f"{name}.Notification.Messages", (MT, "Messages"), m.MESSAGES.node, notifier=True
    )
    eq = b.child_object(root, f"{name}.Equipment", (MT, "Equipment"), m.EQUIPMENT.node)
    b.child_object(eq, f"{name}.Equipment.Tools", (MT, "Tools"), m.TOOL_LIST.node)
    return root


def _identification(b: Builder, root: ua.NodeId, name: str, ident: Identification) -> None:
    idn = b.child_object(
        root,
        f"{name}.Identification",
        (m.DI, "Identification"),
        m.MACHINE_TOOL_IDENTIFICATION.node,
        ref=m.HAS_ADD_IN,
    )
    uri = f"urn:fmscell:{ident.manufacturer}:{ident.model}:{ident.serial_number}"
    b.values(
        idn,
        f"{name}.Identification",
        (
            ((m.DI, "Manufacturer"), m.LOCALIZED_TEXT, ident.manufacturer),
            ((m.DI, "SerialNumber"), m.STRING, ident.serial_number),
            ((m.DI, "ProductInstanceUri"), m.STRING, uri),
            ((m.DI, "Model"), m.LOCALIZED_TEXT, ident.model),
            ((m.DI, "SoftwareRevision"), m.STRING, ident.software_revision),
            ((m.MACHINERY, "Location"), m.STRING, ident.location),
        ),
        prop=True,
    )


def _operation(b: Builder, mon: ua.NodeId, p: str) -> None:
    op = b.child_object(mon, p, (MT, "MachineTool"), m.MACHINE_OPERATION_MONITORING.node)
    b.values(
        op,
        p,
        (
            ((MT, "OperationMode"), m.MACHINE_OPERATION_MODE.node, 1),
            ((MT, "PowerOnDuration"), m.UINT32, 0),
        ),
    )
    b.override(op, f"{p}.FeedOverride", (MT, "FeedOverride"))
    for name, typedef, initial in (
        ("MachineryItemState", m.MACHINERY_ITEM_STATE.node, "NotExecuting"),
        ("MachineryOperationMode", m.MACHINE_OPERATION_MODE_STATE_MACHINE.node, "Processing"),
    ):
        b.state(op, p, typedef, initial, (m.MACHINERY, name))


def _channel(
    b: Builder, mon: ua.NodeId, p: str, axes: tuple[str, ...], methods: Mapping[str, Callable]
) -> None:
    ch = b.child_object(mon, p, (MT, "Channel1"), m.CHANNEL_MONITORING.node)
    b.value(ch, f"{p}.Name", (MT, "Name"), m.STRING, "Channel1", prop=True)
    b.values(
        ch,
        p,
        (
            ((MT, "ChannelState"), m.CHANNEL_STATE.node, 2),
            ((MT, "ChannelMode"), m.CHANNEL_MODE.node, 0),
        ),
    )
    for what in ("FeedOverride", "RapidOverride"):
        b.override(ch, f"{p}.{what}", (MT, what))
    mods = b.child_object(
        ch, f"{p}.ChannelModifiers", (MT, "ChannelModifiers"), m.CHANNEL_MODIFIER.node
    )
    b.values(
        mods,
        f"{p}.ChannelModifiers",
        tuple(
            ((MT, k), m.BOOLEAN, False)
            for k in ("BlockSkip", "DryRun", "OptionalStop", "SingleStep")
        ),
    )
    b.values(ch, p, (((FMS, "Line"), m.UINT32, 0), ((FMS, "PathFeedRate"), m.DOUBLE, 0.0)))
    for axis in axes:
        ax = b.child_object(ch, f"{p}.{axis}", (FMS, axis), m.BASE_OBJECT)
        b.value(ax, f"{p}.{axis}.ActualPosition", (FMS, "ActualPosition"), m.DOUBLE, 0.0)
    for method, callback in methods.items():
        b.method(ch, f"{p}.{method}", (FMS, method), callback)


def _spindle(b: Builder, mon: ua.NodeId, p: str) -> None:
    sp_node = b.child_object(mon, p, (MT, "Spindle"), m.SPINDLE_MONITORING.node)
    b.value(sp_node, f"{p}.Name", (MT, "Name"), m.STRING, "Spindle", prop=True)
    # the machines' spindles never serve as a C axis (a lathe's C is a separate axis)
    b.values(
        sp_node,
        p,
        (((MT, "IsRotating"), m.BOOLEAN, False), ((MT, "IsUsedAsAxis"), m.BOOLEAN, False)),
    )
    b.override(sp_node, f"{p}.Override", (MT, "Override"))
    b.value(sp_node, f"{p}.Speed", (FMS, "Speed"), m.DOUBLE, 0.0)


def _stacklight(b: Builder, mon: ua.NodeId, p: str) -> None:
    sl = b.child_object(mon, p, (MT, "Stacklight"), m.BASIC_STACKLIGHT.node)
    b.value(
        sl,
        f"{p}.StacklightMode",
        (m.IA, "StacklightMode"),
        m.STACKLIGHT_OPERATION_MODE.node,
        0,
        prop=True,
    )
    for i, (lamp, lamp_color) in enumerate(STACK_LAMPS):
        el = b.ordered(sl, f"{p}.{lamp}", (FMS, lamp), m.STACK_ELEMENT_LIGHT.node, i, m.UINTEGER)
        b.value(el, f"{p}.{lamp}.SignalOn", (m.IA, "SignalOn"), m.BOOLEAN, False, prop=True)
        b.value(
            el,
            f"{p}.{lamp}.SignalColor",
            (m.IA, "SignalColor"),
            m.SIGNAL_COLOR.node,
            color(lamp_color),
        )
        # the lamps are steady: the simulated machines do not blink them
        b.value(el, f"{p}.{lamp}.SignalMode", (m.IA, "SignalMode"), m.SIGNAL_MODE_LIGHT.node, 0)


def _active_program(b: Builder, prod: ua.NodeId, p: str) -> None:
    ap = b.child_object(prod, p, (MT, "ActiveProgram"), m.PRODUCTION_ACTIVE_PROGRAM.node)
    b.value(ap, f"{p}.Name", (MT, "Name"), m.STRING, "", prop=True)
    b.value(ap, f"{p}.NumberInList", (m.UA, "NumberInList"), m.UINT16, 0, prop=True)
    b.state(ap, p, m.PRODUCTION_PROGRAM_STATE_MACHINE.node, "Initializing")
    b.values(
        ap,
        p,
        (
            ((MT, "JobIdentifier"), m.STRING, ""),
            ((MT, "JobNodeId"), m.NODE_ID, None),
            ((FMS, "Number"), m.UINT32, 0),
            ((FMS, "Line"), m.UINT32, 0),
            ((FMS, "PartCount"), m.UINT32, 0),
            ((FMS, "Sha256"), m.STRING, ""),
            ((FMS, "Revision"), m.STRING, ""),
        ),
    )


def production_job(b: Builder, plan: ua.NodeId, p: str, job: ProductionJob, i: int) -> ua.NodeId:
    """A ProductionJob under the ProductionPlan, with its one ProductionProgram."""
    node = b.ordered(plan, p, (FMS, job.identifier), m.PRODUCTION_JOB.node, i)
    b.value(node, f"{p}.Identifier", (MT, "Identifier"), m.STRING, job.identifier, prop=True)
    b.values(
        node,
        p,
        tuple(((MT, k), m.UINT32, 0) for k in ("RunsPlanned", "RunsCompleted", "PartsCompleted")),
    )
    # the host always plans a quantity, so RunsPlanned is always valid
    b.value(
        ua.NodeId(f"{p}.RunsPlanned", b.space.machine_ns),
        f"{p}.RunsPlanned.IsValid",
        (MT, "IsValid"),
        m.BOOLEAN,
        True,
        prop=True,
    )
    b.state(node, p, m.PRODUCTION_JOB_STATE_MACHINE.node, "")
    progs = b.child_object(
        node, f"{p}.ProductionPrograms", (MT, "ProductionPrograms"), m.ORDERED_LIST
    )
    q = f"{p}.ProductionPrograms.{job.program}"
    prog = b.ordered(progs, q, (FMS, job.program), m.PRODUCTION_PROGRAM.node, 0)
    b.value(prog, f"{q}.Name", (MT, "Name"), m.STRING, job.program, prop=True)
    return node


def tool(b: Builder, tools: ua.NodeId, p: str, number: str, data: dict) -> ua.NodeId:
    """A ToolType entry of the tool list, with its life counters under ToolLife."""
    node = b.child_object(tools, p, (FMS, f"T{number}"), m.TOOL.node)
    b.values(
        node,
        p,
        (
            ((MT, "Name"), m.STRING, data.get("comment") or f"T{number}"),
            ((MT, "Identifier"), m.STRING, f"T{number}"),
        ),
        prop=True,
    )
    b.values(
        node,
        p,
        (
            ((MT, "ControlIdentifier1"), m.UINT32, int(number)),
            ((MT, "ControlIdentifierInterpretation"), m.TOOL_MANAGEMENT.node, 0),
            ((MT, "Locked"), m.BOOLEAN, False),
        ),
    )
    b.value(
        ua.NodeId(f"{p}.Locked", b.space.machine_ns),
        f"{p}.Locked.ReasonForLocking",
        (MT, "ReasonForLocking"),
        m.TOOL_LOCKED.node,
        LOCKED_BY_TOOL_LIFE,
        prop=True,
    )
    life = b.child_object(node, f"{p}.ToolLife", (MT, "ToolLife"), m.BASE_OBJECT)
    uses, hours = tool_limits(data)
    q = f"{p}.ToolLife"
    b.tool_life(life, f"{q}.Uses", (FMS, "Uses"), m.UINT32, "NumberOfUsages", ONE, uses)
    b.tool_life(life, f"{q}.CutTime", (FMS, "CutTime"), m.DOUBLE, "Time", HOUR, hours)
    return node


#: the only reason the machine locks a tool (ReasonForLocking: meaningful while Locked)
LOCKED_BY_TOOL_LIFE = m.TOOL_LOCKED.fields.index("ToolLife")


def tool_limits(data: dict) -> tuple[int | None, float | None]:
    """The tool's life limits as ToolLife LimitValues: usages, and cutting time in hours
    (OPC 40501-1 counts time in hours); None where the tool has no limit (0 in the tool
    table), so the entry has no LimitValue."""
    uses = int(data["life_uses"]) if data["life_uses"] > 0 else None
    hours = float(data["life_time_s"]) / 3600.0 if data["life_time_s"] > 0 else None
    return uses, hours


def tool_values(data: dict) -> dict[str, object]:
    """A tool offset's live values, keyed under the tool's node (pure)."""
    expired = (data["life_uses"] > 0 and data["uses"] >= data["life_uses"]) or (
        data["life_time_s"] > 0 and data["cut_time_s"] >= data["life_time_s"]
    )
    uses, hours = tool_limits(data)
    out: dict[str, object] = {
        "Locked": expired,
        "ToolLife.Uses": int(data["uses"]),
        "ToolLife.CutTime": float(data["cut_time_s"]) / 3600.0,
    }
    if uses is not None:
        out["ToolLife.Uses.LimitValue"] = uses
    if hours is not None:
        out["ToolLife.CutTime.LimitValue"] = hours
    return out


def job_values(job: ProductionJob, i: int) -> dict[str, object]:
    return {
        "NumberInList": i,
        "RunsPlanned": job.runs_planned,
        "RunsCompleted": job.runs_completed,
        "PartsCompleted": job.parts_completed,
        **current_state("State", m.JOB_STATES, job.state),
    }
