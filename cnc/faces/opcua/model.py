"""The OPC UA information model the machine's server uses, declared from the companion
specifications: OPC 10000-100 (DI), OPC 40001-1 (Machinery), OPC 10000-200 (IA, stack
light) and OPC 40501-1 v1.02 (MachineTool).

These are facts of the specifications (namespace URIs, numeric node ids, browse names,
supertypes, modelling rules, data types), written out for the subset the server fills, so
the server builds its type nodes itself at start instead of importing the NodeSet2 files
at run time. Tests parse the official NodeSet2 files and check every declaration here
against them (tests/cnc/test_opcua_model.py).

A node is named `(namespace URI, numeric id)`; a browse name `(namespace URI, name)`.
"""

from __future__ import annotations

from dataclasses import dataclass

UA = "http://opcfoundation.org/UA/"
DI = "http://opcfoundation.org/UA/DI/"
MACHINERY = "http://opcfoundation.org/UA/Machinery/"
IA = "http://opcfoundation.org/UA/IA/"
MACHINE_TOOL = "http://opcfoundation.org/UA/MachineTool/"
#: fmscell's own extensions (program line, DNC revision and sha256): a namespace of ours
FMSCELL = "urn:fmscell:opcua"

#: the order the server registers the companion namespaces in (any order would do: a
#: client resolves URIs through the NamespaceArray)
COMPANION_URIS = (DI, MACHINERY, IA, MACHINE_TOOL, FMSCELL)

NodeRef = tuple[str, int]
Name = tuple[str, str]

# --- standard nodes (namespace 0) used as supertypes, type definitions and data types -----
BASE_OBJECT = (UA, 58)
FOLDER = (UA, 61)
BASE_DATA_VARIABLE = (UA, 63)
PROPERTY = (UA, 68)
ENUMERATION = (UA, 29)
FINITE_STATE_MACHINE = (UA, 2771)
FINITE_STATE_VARIABLE = (UA, 2760)
ORDERED_LIST = (UA, 23518)
ANALOG_UNIT_RANGE = (UA, 17570)
BOOLEAN, BYTE, UINT16, UINT32, DOUBLE, STRING = (
    (UA, 1),
    (UA, 3),
    (UA, 5),
    (UA, 7),
    (UA, 11),
    (UA, 12),
)
LOCALIZED_TEXT = (UA, 21)
NODE_ID = (UA, 17)
UINTEGER = (UA, 28)  # abstract: any unsigned integer
NUMBER = (UA, 26)  # abstract: any number
EU_INFORMATION = (UA, 887)
RANGE = (UA, 884)

HAS_COMPONENT, HAS_PROPERTY, HAS_ADD_IN, HAS_ORDERED_COMPONENT = 47, 46, 17604, 49
MANDATORY, OPTIONAL, OPTIONAL_PLACEHOLDER = 78, 80, 11510


@dataclass(frozen=True, slots=True)
class Member:
    """An instance declaration of a type (a component, property or add-in)."""

    name: Name
    node_id: int  # in the declaring type's namespace
    node_class: str  # "Object" | "Variable"
    type_definition: NodeRef
    mandatory: bool
    reference: int = HAS_COMPONENT
    data_type: NodeRef | None = None
    #: the declaration's own members (an instance declaration may add to or refine what
    #: its type definition declares: a state machine's CurrentState with Id and Number)
    children: tuple[Member, ...] = ()


@dataclass(frozen=True, slots=True)
class ObjectTypeDecl:
    node: NodeRef
    name: str  # browse name, in the node's namespace
    supertype: NodeRef
    members: tuple[Member, ...] = ()
    abstract: bool = False


@dataclass(frozen=True, slots=True)
class VariableTypeDecl:
    node: NodeRef
    name: str  # browse name, in the node's namespace
    supertype: NodeRef
    data_type: NodeRef
    members: tuple[Member, ...] = ()


@dataclass(frozen=True, slots=True)
class EnumDecl:
    node: NodeRef
    name: str
    fields: tuple[str, ...]  # values 0, 1, 2, ... in order


def _v(
    ns: str,
    name: str,
    node_id: int,
    data_type: NodeRef,
    mandatory: bool,
    *,
    prop: bool = False,
    name_ns: str | None = None,
    typedef: NodeRef | None = None,
    children: tuple[Member, ...] = (),
) -> Member:
    return Member(
        (name_ns or ns, name),
        node_id,
        "Variable",
        typedef or (PROPERTY if prop else BASE_DATA_VARIABLE),
        mandatory,
        HAS_PROPERTY if prop else HAS_COMPONENT,
        data_type,
        children,
    )


def _o(
    ns: str,
    name: str,
    node_id: int,
    typedef: NodeRef,
    mandatory: bool,
    *,
    ref: int = HAS_COMPONENT,
    children: tuple[Member, ...] = (),
) -> Member:
    return Member((ns, name), node_id, "Object", typedef, mandatory, ref, children=children)


def _override(ns: str, name: str, node_id: int, mandatory: bool, units: int, eu_range: int):
    """An AnalogUnitRange override with its two mandatory properties (OPC 10000-8)."""
    return _v(
        ns,
        name,
        node_id,
        DOUBLE,
        mandatory,
        typedef=ANALOG_UNIT_RANGE,
        children=(
            _v(ns, "EngineeringUnits", units, EU_INFORMATION, True, prop=True, name_ns=UA),
            _v(ns, "EURange", eu_range, RANGE, True, prop=True, name_ns=UA),
        ),
    )


def _current_state(ns: str, node_id: int, id_id: int, number_id: int | None = None) -> Member:
    """A state machine's CurrentState (FiniteStateVariable) with its Id (the NodeId of the
    current state) and, where the declaration makes it mandatory, its Number."""
    children = [_v(ns, "Id", id_id, NODE_ID, True, prop=True, name_ns=UA)]
    if number_id is not None:
        children.append(_v(ns, "Number", number_id, UINT32, True, prop=True, name_ns=UA))
    return _v(
        ns,
        "CurrentState",
        node_id,
        LOCALIZED_TEXT,
        True,
        name_ns=UA,
        typedef=FINITE_STATE_VARIABLE,
        children=tuple(children),
    )


# --- data types --------------------------------------------------------------------------

CHANNEL_STATE = EnumDecl((MACHINE_TOOL, 64), "ChannelState", ("Active", "Interrupted", "Reset"))
MACHINE_OPERATION_MODE = EnumDecl(
    (MACHINE_TOOL, 65),
    "MachineOperationMode",
    ("Manual", "Automatic", "Setup", "AutoWithManualIntervention", "Service", "Other"),
)
CHANNEL_MODE = EnumDecl(
    (MACHINE_TOOL, 67),
    "ChannelMode",
    (
        "Automatic",
        "MdaMdi",
        "JogManual",
        "JogIncrement",
        "TeachingHandle",
        "Remote",
        "Reference",
        "Other",
    ),
)
TOOL_MANAGEMENT = EnumDecl(
    (MACHINE_TOOL, 69), "ToolManagement", ("NumberBased", "GroupBased", "Other")
)
TOOL_LIFE_INDICATION = EnumDecl(
    (MACHINE_TOOL, 68),
    "ToolLifeIndication",
    (
        "Time",
        "NumberOfParts",
        "NumberOfUsages",
        "Feed_Distance",
        "Cutting_Distance",
        "Length",
        "Diameter",
        "Other",
    ),
)
TOOL_LOCKED = EnumDecl(
    (MACHINE_TOOL, 66),
    "ToolLocked",
    ("CapabilityUnavailable", "ByOperator", "ToolBreak", "ToolLife", "MeasurementError", "Other"),
)
SIGNAL_MODE_LIGHT = EnumDecl(
    (IA, 3005), "SignalModeLight", ("Continuous", "Blinking", "Flashing", "Other")
)
STACKLIGHT_OPERATION_MODE = EnumDecl(
    (IA, 3002), "StacklightOperationMode", ("Segmented", "Levelmeter", "Running_Light", "Other")
)
SIGNAL_COLOR = EnumDecl(
    (IA, 3004),
    "SignalColor",
    ("Off", "Red", "Green", "Blue", "Yellow", "Purple", "Cyan", "White"),
)
ENUMS = (
    CHANNEL_STATE,
    MACHINE_OPERATION_MODE,
    CHANNEL_MODE,
    TOOL_MANAGEMENT,
    TOOL_LIFE_INDICATION,
    TOOL_LOCKED,
    STACKLIGHT_OPERATION_MODE,
    SIGNAL_COLOR,
    SIGNAL_MODE_LIGHT,
)

# --- object types, supertypes first ------------------------------------------------------

MT, MA = MACHINE_TOOL, MACHINERY

FUNCTIONAL_GROUP = ObjectTypeDecl((DI, 1005), "FunctionalGroupType", FOLDER)
MACHINERY_ITEM_IDENTIFICATION = ObjectTypeDecl(
    (MA, 1004),
    "MachineryItemIdentificationType",
    FUNCTIONAL_GROUP.node,
    (
        _v(MA, "Manufacturer", 6002, LOCALIZED_TEXT, True, prop=True, name_ns=DI),
        _v(MA, "SerialNumber", 6003, STRING, True, prop=True, name_ns=DI),
        _v(MA, "Model", 6008, LOCALIZED_TEXT, False, prop=True, name_ns=DI),
        _v(MA, "SoftwareRevision", 6011, STRING, False, prop=True, name_ns=DI),
    ),
    abstract=True,
)
MACHINE_IDENTIFICATION = ObjectTypeDecl(
    (MA, 1012),
    "MachineIdentificationType",
    MACHINERY_ITEM_IDENTIFICATION.node,
    (
        _v(MA, "ProductInstanceUri", 6015, STRING, True, prop=True, name_ns=DI),
        _v(MA, "Location", 6029, STRING, False, prop=True),
    ),
)
MACHINE_TOOL_IDENTIFICATION = ObjectTypeDecl(
    (MT, 11), "MachineToolIdentificationType", MACHINE_IDENTIFICATION.node
)

ELEMENT_MONITORING = ObjectTypeDecl(
    (MT, 23),
    "ElementMonitoringType",
    BASE_OBJECT,
    (_v(MT, "Name", 234, STRING, True, prop=True),),
)
# OPC 40001-1 state machines; their states and transitions are not instance declarations
# (no modelling rule): an instance shows its state in CurrentState
MACHINERY_ITEM_STATE = ObjectTypeDecl(
    (MA, 1002), "MachineryItemState_StateMachineType", FINITE_STATE_MACHINE
)
MACHINERY_OPERATION_MODE = ObjectTypeDecl(
    (MA, 1008), "MachineryOperationModeStateMachineType", FINITE_STATE_MACHINE
)
#: 40501's own subtype (a MaintenanceMode sub-state machine under Maintenance) is what
#: MachineTool's MachineryOperationMode is declared with
MACHINE_OPERATION_MODE_STATE_MACHINE = ObjectTypeDecl(
    (MT, 1003), "MachineOperationModeStateMachineType", MACHINERY_OPERATION_MODE.node
)
MACHINE_OPERATION_MONITORING = ObjectTypeDecl(
    (MT, 26),
    "MachineOperationMonitoringType",
    BASE_OBJECT,
    (
        _v(MT, "OperationMode", 225, MACHINE_OPERATION_MODE.node, True),
        _v(MT, "PowerOnDuration", 261, UINT32, False),
        _override(MT, "FeedOverride", 233, False, 237, 252),
        _o(
            MA,
            "MachineryItemState",
            5006,
            MACHINERY_ITEM_STATE.node,
            False,
            children=(_current_state(MT, 6007, 6008),),
        ),
        _o(
            MA,
            "MachineryOperationMode",
            5007,
            MACHINE_OPERATION_MODE_STATE_MACHINE.node,
            False,
            children=(_current_state(MT, 6009, 6010),),
        ),
    ),
)
CHANNEL_MODIFIER = ObjectTypeDecl(
    (MT, 33),
    "ChannelModifierType",
    BASE_OBJECT,
    (
        _v(MT, "BlockSkip", 248, BOOLEAN, False),
        _v(MT, "DryRun", 340, BOOLEAN, True),
        _v(MT, "OptionalStop", 325, BOOLEAN, True),
        _v(MT, "SingleStep", 317, BOOLEAN, True),
    ),
)
CHANNEL_MONITORING = ObjectTypeDecl(
    (MT, 16),
    "ChannelMonitoringType",
    ELEMENT_MONITORING.node,
    (
        _v(MT, "ChannelState", 332, CHANNEL_STATE.node, True),
        _v(MT, "ChannelMode", 249, CHANNEL_MODE.node, True),
        _override(MT, "FeedOverride", 276, True, 335, 336),
        _override(MT, "RapidOverride", 287, False, 342, 343),
        _o(
            MT,
            "ChannelModifiers",
            113,
            CHANNEL_MODIFIER.node,
            False,
            children=(
                _v(MT, "BlockSkip", 383, BOOLEAN, False),
                _v(MT, "DryRun", 361, BOOLEAN, True),
                _v(MT, "OptionalStop", 364, BOOLEAN, True),
                _v(MT, "SingleStep", 367, BOOLEAN, True),
            ),
        ),
    ),
)
WORKING_UNIT_MONITORING = ObjectTypeDecl(
    (MT, 41), "WorkingUnitMonitoringType", ELEMENT_MONITORING.node, abstract=True
)
SPINDLE_MONITORING = ObjectTypeDecl(
    (MT, 22),
    "SpindleMonitoringType",
    WORKING_UNIT_MONITORING.node,
    (
        _v(MT, "IsRotating", 247, BOOLEAN, True),
        _override(MT, "Override", 241, False, 246, 275),
        _v(MT, "IsUsedAsAxis", 371, BOOLEAN, False),
    ),
)
STACK_ELEMENT = ObjectTypeDecl(
    (IA, 1005),
    "StackElementType",
    BASE_OBJECT,
    (
        _v(IA, "NumberInList", 6015, UINTEGER, True, prop=True, name_ns=UA),
        _v(IA, "SignalOn", 6013, BOOLEAN, False, prop=True),
    ),
    abstract=True,
)
STACK_ELEMENT_LIGHT = ObjectTypeDecl(
    (IA, 1006),
    "StackElementLightType",
    STACK_ELEMENT.node,
    (
        _v(IA, "SignalColor", 6016, SIGNAL_COLOR.node, False),
        _v(IA, "SignalMode", 6017, SIGNAL_MODE_LIGHT.node, False),
    ),
)
BASIC_STACKLIGHT = ObjectTypeDecl(
    (IA, 1002),
    "BasicStacklightType",
    ORDERED_LIST,
    (_v(IA, "StacklightMode", 6009, STACKLIGHT_OPERATION_MODE.node, True, prop=True),),
)
MONITORING = ObjectTypeDecl(
    (MT, 14),
    "MonitoringType",
    BASE_OBJECT,
    (
        _o(
            MT,
            "MachineTool",
            119,
            MACHINE_OPERATION_MONITORING.node,
            True,
            children=(_v(MT, "OperationMode", 254, MACHINE_OPERATION_MODE.node, True),),
        ),
        _o(
            MT,
            "Stacklight",
            121,
            BASIC_STACKLIGHT.node,
            False,
            children=(
                _v(
                    MT,
                    "StacklightMode",
                    415,
                    STACKLIGHT_OPERATION_MODE.node,
                    True,
                    prop=True,
                    name_ns=IA,
                ),
            ),
        ),
    ),
)

PRODUCTION_STATE_MACHINE = ObjectTypeDecl(
    (MT, 24),
    "ProductionStateMachineType",
    FINITE_STATE_MACHINE,
    (_current_state(MT, 270, 271, 274),),
)
PRODUCTION_PROGRAM_STATE_MACHINE = ObjectTypeDecl(
    (MT, 15), "ProductionProgramStateMachineType", PRODUCTION_STATE_MACHINE.node
)
PRODUCTION_JOB_STATE_MACHINE = ObjectTypeDecl(
    (MT, 28), "ProductionJobStateMachineType", PRODUCTION_STATE_MACHINE.node
)
PRODUCTION_PROGRAM = ObjectTypeDecl(
    (MT, 59),
    "ProductionProgramType",
    BASE_OBJECT,
    (
        _v(MT, "Name", 193, STRING, True, prop=True),
        _v(MT, "NumberInList", 230, UINT16, True, prop=True, name_ns=UA),
        _o(
            MT,
            "State",
            5032,
            PRODUCTION_PROGRAM_STATE_MACHINE.node,
            False,
            children=(_current_state(MT, 6031, 6035, 6039),),
        ),
    ),
)
PRODUCTION_ACTIVE_PROGRAM = ObjectTypeDecl(
    (MT, 32),
    "ProductionActiveProgramType",
    PRODUCTION_PROGRAM.node,
    (
        _o(
            MT,
            "State",
            5033,
            PRODUCTION_PROGRAM_STATE_MACHINE.node,
            True,
            children=(_current_state(MT, 6032, 6033, 6034),),
        ),
        _v(MT, "JobIdentifier", 384, STRING, False),
        _v(MT, "JobNodeId", 382, NODE_ID, False),
    ),
)
PRODUCTION_JOB = ObjectTypeDecl(
    (MT, 29),
    "ProductionJobType",
    BASE_OBJECT,
    (
        _v(MT, "Identifier", 189, STRING, True, prop=True),
        _v(MT, "NumberInList", 196, UINT16, True, prop=True, name_ns=UA),
        _v(
            MT,
            "RunsPlanned",
            192,
            UINT32,
            True,
            children=(_v(MT, "IsValid", 188, BOOLEAN, True, prop=True),),
        ),
        _v(MT, "RunsCompleted", 191, UINT32, True),
        _o(
            MT,
            "State",
            5002,
            PRODUCTION_JOB_STATE_MACHINE.node,
            True,
            children=(_current_state(MT, 6001, 6002, 6003),),
        ),
        _o(MT, "ProductionPrograms", 75, ORDERED_LIST, True),
        _v(MT, "PartsCompleted", 6015, UINT32, False),
    ),
)
PRODUCTION_JOB_LIST = ObjectTypeDecl((MT, 30), "ProductionJobListType", ORDERED_LIST)
PRODUCTION = ObjectTypeDecl(
    (MT, 21),
    "ProductionType",
    BASE_OBJECT,
    (
        _o(
            MT,
            "ActiveProgram",
            87,
            PRODUCTION_ACTIVE_PROGRAM.node,
            True,
            children=(
                _v(MT, "Name", 326, STRING, True, prop=True),
                _v(MT, "NumberInList", 250, UINT16, True, prop=True, name_ns=UA),
                _o(
                    MT,
                    "State",
                    5035,
                    PRODUCTION_PROGRAM_STATE_MACHINE.node,
                    True,
                    children=(_current_state(MT, 6040, 6041, 6042),),
                ),
            ),
        ),
        _o(MT, "ProductionPlan", 81, PRODUCTION_JOB_LIST.node, False),
    ),
)

MESSAGES = ObjectTypeDecl((MT, 38), "MessagesType", BASE_OBJECT)
NOTIFICATION = ObjectTypeDecl(
    (MT, 7), "NotificationType", BASE_OBJECT, (_o(MT, "Messages", 90, MESSAGES.node, False),)
)

BASE_TOOL = ObjectTypeDecl(
    (MT, 49),
    "BaseToolType",
    BASE_OBJECT,
    (
        _v(MT, "Name", 176, STRING, False, prop=True),
        _v(MT, "Identifier", 316, STRING, False, prop=True),
    ),
    abstract=True,
)
#: OPC 40501-1 §11.1: one tool life counter (a Number) with how it counts and its unit;
#: a tool's ToolLife object holds any number of them (<ToolLifeEntry>)
TOOL_LIFE = VariableTypeDecl(
    (MT, 61),
    "ToolLifeType",
    BASE_DATA_VARIABLE,
    NUMBER,
    (
        _v(MT, "EngineeringUnits", 285, EU_INFORMATION, True, prop=True),
        _v(MT, "Indication", 286, TOOL_LIFE_INDICATION.node, True, prop=True),
        _v(MT, "IsCountingUp", 411, BOOLEAN, True, prop=True),
        _v(MT, "LimitValue", 305, NUMBER, False, prop=True),
        _v(MT, "StartValue", 304, NUMBER, False, prop=True),
        _v(MT, "WarningValue", 306, NUMBER, False, prop=True),
    ),
)
#: the placeholder under ToolType's ToolLife (ns=MT;i=88) that the tool life entries of an
#: instance stand for
TOOL_LIFE_ENTRY = Member(
    (MT, "<ToolLifeEntry>"), 283, "Variable", TOOL_LIFE.node, False, HAS_COMPONENT, NUMBER
)
TOOL_LIFE_OBJECT = 88  # ToolType's ToolLife, in MT

TOOL = ObjectTypeDecl(
    (MT, 50),
    "ToolType",
    BASE_TOOL.node,
    (
        _v(MT, "ControlIdentifier1", 178, UINT32, True),
        _v(MT, "ControlIdentifierInterpretation", 296, TOOL_MANAGEMENT.node, True),
        _v(
            MT,
            "Locked",
            321,
            BOOLEAN,
            True,
            children=(_v(MT, "ReasonForLocking", 269, TOOL_LOCKED.node, True, prop=True),),
        ),
        _o(MT, "ToolLife", 88, BASE_OBJECT, False),
    ),
)
TOOL_LIST = ObjectTypeDecl((MT, 44), "ToolListType", BASE_OBJECT)
EQUIPMENT = ObjectTypeDecl(
    (MT, 12), "EquipmentType", BASE_OBJECT, (_o(MT, "Tools", 116, TOOL_LIST.node, False),)
)

MACHINE_TOOL_TYPE = ObjectTypeDecl(
    (MT, 13),
    "MachineToolType",
    BASE_OBJECT,
    (
        _o(
            DI,
            "Identification",
            83,
            MACHINE_TOOL_IDENTIFICATION.node,
            True,
            ref=HAS_ADD_IN,
            children=(
                _v(MT, "Manufacturer", 182, LOCALIZED_TEXT, True, prop=True, name_ns=DI),
                _v(MT, "ProductInstanceUri", 258, STRING, True, prop=True, name_ns=DI),
                _v(MT, "SerialNumber", 259, STRING, True, prop=True, name_ns=DI),
            ),
        ),
        _o(
            MT,
            "Monitoring",
            123,
            MONITORING.node,
            True,
            children=(
                _o(
                    MT,
                    "MachineTool",
                    122,
                    MACHINE_OPERATION_MONITORING.node,
                    True,
                    children=(_v(MT, "OperationMode", 263, MACHINE_OPERATION_MODE.node, True),),
                ),
            ),
        ),
        _o(
            MT,
            "Production",
            82,
            PRODUCTION.node,
            True,
            children=(
                _o(
                    MT,
                    "ActiveProgram",
                    84,
                    PRODUCTION_ACTIVE_PROGRAM.node,
                    True,
                    children=(
                        _v(MT, "Name", 174, STRING, True, prop=True),
                        _v(MT, "NumberInList", 175, UINT16, True, prop=True, name_ns=UA),
                        _o(
                            MT,
                            "State",
                            5034,
                            PRODUCTION_PROGRAM_STATE_MACHINE.node,
                            True,
                            children=(_current_state(MT, 6036, 6037, 6038),),
                        ),
                    ),
                ),
            ),
        ),
        _o(MT, "Notification", 128, NOTIFICATION.node, True),
        _o(MT, "Equipment", 131, EQUIPMENT.node, True),
    ),
)

#: every object type the server declares, each after its supertype and member types
OBJECT_TYPES = (
    CHANNEL_MODIFIER,
    FUNCTIONAL_GROUP,
    MACHINERY_ITEM_IDENTIFICATION,
    MACHINE_IDENTIFICATION,
    MACHINE_TOOL_IDENTIFICATION,
    ELEMENT_MONITORING,
    MACHINERY_ITEM_STATE,
    MACHINERY_OPERATION_MODE,
    MACHINE_OPERATION_MODE_STATE_MACHINE,
    MACHINE_OPERATION_MONITORING,
    CHANNEL_MONITORING,
    WORKING_UNIT_MONITORING,
    SPINDLE_MONITORING,
    STACK_ELEMENT,
    STACK_ELEMENT_LIGHT,
    BASIC_STACKLIGHT,
    MONITORING,
    PRODUCTION_STATE_MACHINE,
    PRODUCTION_PROGRAM_STATE_MACHINE,
    PRODUCTION_JOB_STATE_MACHINE,
    PRODUCTION_PROGRAM,
    PRODUCTION_ACTIVE_PROGRAM,
    PRODUCTION_JOB,
    PRODUCTION_JOB_LIST,
    PRODUCTION,
    MESSAGES,
    NOTIFICATION,
    BASE_TOOL,
    TOOL,
    TOOL_LIST,
    EQUIPMENT,
    MACHINE_TOOL_TYPE,
)

#: every variable type the server declares
VARIABLE_TYPES = (TOOL_LIFE,)

#: Objects/Machines, the Machinery entry point every machine registers under
MACHINES_FOLDER: NodeRef = (MA, 1001)

#: the states of each state machine the instance holds: the state's node (what the Id of
#: CurrentState names) and its StateNumber (what Number shows), from the nodesets
PROGRAM_STATES: dict[str, tuple[NodeRef, int]] = {  # ProductionProgramStateMachineType
    "Initializing": ((MT, 5039), 0),
    "Running": ((MT, 5041), 1),
    "Ended": ((MT, 5038), 2),
    "Interrupted": ((MT, 5040), 3),
    "Aborted": ((MT, 5037), 4),
}
JOB_STATES: dict[str, tuple[NodeRef, int]] = {  # ProductionJobStateMachineType
    "Initializing": ((MT, 5015), 0),
    "Running": ((MT, 5017), 1),
    "Ended": ((MT, 5014), 2),
    "Interrupted": ((MT, 5016), 3),
    "Aborted": ((MT, 5013), 4),
}
MACHINERY_ITEM_STATES: dict[str, tuple[NodeRef, int]] = {  # MachineryItemState_StateMachine
    "NotAvailable": ((MA, 5005), 0),
    "OutOfService": ((MA, 5004), 1),
    "NotExecuting": ((MA, 5007), 2),
    "Executing": ((MA, 5006), 3),
}
MACHINE_OPERATION_MODES: dict[str, tuple[NodeRef, int]] = {  # MachineOperationModeSM
    "None": ((MT, 5059), 0),
    "Maintenance": ((MT, 5058), 1),
    "Setup": ((MT, 5061), 2),
    "Processing": ((MT, 5060), 3),
}
#: each state machine type the instance uses -> its states
STATES_OF: dict[NodeRef, dict[str, tuple[NodeRef, int]]] = {
    PRODUCTION_PROGRAM_STATE_MACHINE.node: PROGRAM_STATES,
    PRODUCTION_JOB_STATE_MACHINE.node: JOB_STATES,
    MACHINERY_ITEM_STATE.node: MACHINERY_ITEM_STATES,
    MACHINE_OPERATION_MODE_STATE_MACHINE.node: MACHINE_OPERATION_MODES,
}
