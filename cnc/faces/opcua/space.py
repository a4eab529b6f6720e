"""Builds the machine's address space in an asyncua server: the companion types from
`model.py`, then the MachineTool instance under Objects/Machines.

Nodes are added through the server's node management service with explicit type
definitions (no automatic instantiation), so the instance holds exactly the members this
module names, with stable string node ids (`<machine>.Monitoring.Channel1.ChannelState`) in
the machine's own namespace.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from asyncua import Server, ua

from cnc.faces.opcua import model as m

PERCENT = ua.EUInformation(
    NamespaceUri="http://www.opcfoundation.org/UA/units/un/cefact",
    UnitId=20529,  # UNECE P1
    DisplayName=ua.LocalizedText("%"),
    Description=ua.LocalizedText("percent"),
)
#: tool life units (OPC 40501-1 §12.8: usages count in "one", time in hours)
ONE = ua.EUInformation(
    NamespaceUri="http://www.opcfoundation.org/UA/units/un/cefact",
    UnitId=4404786,  # UNECE C62
    DisplayName=ua.LocalizedText(""),
    Description=ua.LocalizedText("one"),
)
HOUR = ua.EUInformation(
    NamespaceUri="http://www.opcfoundation.org/UA/units/un/cefact",
    UnitId=4740434,  # UNECE HUR
    DisplayName=ua.LocalizedText("h"),
    Description=ua.LocalizedText("hour"),
)

VARIANT_OF = {
    m.BOOLEAN: ua.VariantType.Boolean,
    m.BYTE: ua.VariantType.Byte,
    m.UINTEGER: ua.VariantType.UInt16,
    m.UINT16: ua.VariantType.UInt16,
    m.UINT32: ua.VariantType.UInt32,
    m.DOUBLE: ua.VariantType.Double,
    m.STRING: ua.VariantType.String,
    m.LOCALIZED_TEXT: ua.VariantType.LocalizedText,
    m.NODE_ID: ua.VariantType.NodeId,
    m.EU_INFORMATION: ua.VariantType.ExtensionObject,
    m.RANGE: ua.VariantType.ExtensionObject,
}


@dataclass
class Space:
    """Namespace indexes and the node ids the updater writes, by key."""

    ns: dict[str, int]
    machine_ns: int
    root: ua.NodeId | None = None
    variables: dict[str, tuple[ua.NodeId, ua.VariantType]] = field(default_factory=dict)

    def node(self, ref: m.NodeRef) -> ua.NodeId:
        uri, ident = ref
        return ua.NodeId(ident, 0 if uri == m.UA else self.ns[uri])

    def qname(self, name: m.Name) -> ua.QualifiedName:
        uri, text = name
        return ua.QualifiedName(text, 0 if uri == m.UA else self.ns[uri])


class Builder:
    def __init__(self, server: Server, space: Space) -> None:
        self.server = server
        self.space = space
        self._items: list[ua.AddNodesItem] = []

    # ------------------------------------------------------------------ raw node adds

    def _add(self, item: ua.AddNodesItem) -> None:
        result = self.server.iserver.node_mgt_service.add_nodes([item])[0]
        if not result.StatusCode.is_good():
            raise RuntimeError(f"OPC UA: cannot add {item.BrowseName}: {result.StatusCode}")

    def _ref(self, source: ua.NodeId, ref: int, target: ua.NodeId) -> None:
        item = ua.AddReferencesItem()
        item.SourceNodeId, item.ReferenceTypeId, item.TargetNodeId = source, ua.NodeId(ref), target
        item.IsForward = True
        item.TargetNodeClass = ua.NodeClass.Object
        self.server.iserver.node_mgt_service.add_references([item])[0].check()

    def object(
        self,
        parent: ua.NodeId,
        nodeid: ua.NodeId,
        name: ua.QualifiedName,
        typedef: ua.NodeId,
        ref: int = m.HAS_COMPONENT,
        notifier: bool = False,
        rule: int | None = None,
    ) -> ua.NodeId:
        attrs = ua.ObjectAttributes()
        attrs.EventNotifier = 1 if notifier else 0
        return self._node(ua.NodeClass.Object, parent, nodeid, name, attrs, ref, typedef, rule)

    def variable(
        self,
        parent: ua.NodeId,
        nodeid: ua.NodeId,
        name: ua.QualifiedName,
        typedef: ua.NodeId,
        data_type: ua.NodeId,
        value: ua.Variant,
        ref: int = m.HAS_COMPONENT,
        rule: int | None = None,
        rank: int = -1,
    ) -> ua.NodeId:
        attrs = ua.VariableAttributes()
        attrs.Value = value
        attrs.DataType = data_type
        attrs.ValueRank = rank
        # read-only for everyone: the machine's state is written by the machine only
        attrs.AccessLevel = attrs.UserAccessLevel = ua.AccessLevel.CurrentRead.mask
        return self._node(ua.NodeClass.Variable, parent, nodeid, name, attrs, ref, typedef, rule)

    def _node(
        self,
        node_class: ua.NodeClass,
        parent: ua.NodeId,
        nodeid: ua.NodeId,
        name: ua.QualifiedName,
        attrs,
        ref: int,
        typedef: ua.NodeId | None = None,
        rule: int | None = None,
    ) -> ua.NodeId:
        """One node of any class under `parent`; every add of this module goes here."""
        item = ua.AddNodesItem()
        item.RequestedNewNodeId, item.BrowseName = nodeid, name
        item.NodeClass = node_class
        item.ParentNodeId, item.ReferenceTypeId = parent, ua.NodeId(ref)
        if typedef is not None:
            item.TypeDefinition = typedef
        attrs.DisplayName = ua.LocalizedText(name.Name)
        item.NodeAttributes = attrs
        self._add(item)
        if rule is not None:
            self._ref(nodeid, ua.ObjectIds.HasModellingRule, ua.NodeId(rule))
        return nodeid

    # ------------------------------------------------------------------ types

    def types(self) -> None:
        sp = self.space
        for enum in m.ENUMS:
            nodeid = self._node(
                ua.NodeClass.DataType,
                sp.node(m.ENUMERATION),
                sp.node(enum.node),
                ua.QualifiedName(enum.name, sp.ns[enum.node[0]]),
                ua.DataTypeAttributes(),
                ua.ObjectIds.HasSubtype,
            )
            self.variable(
                nodeid,
                ua.NodeId(f"{enum.name}.EnumStrings", sp.ns[enum.node[0]]),
                ua.QualifiedName("EnumStrings", 0),
                ua.NodeId(ua.ObjectIds.PropertyType),
                ua.NodeId(ua.ObjectIds.LocalizedText),
                ua.Variant(
                    [ua.LocalizedText(f) for f in enum.fields], ua.VariantType.LocalizedText
                ),
                ref=m.HAS_PROPERTY,
                rank=1,
            )
        for decl in m.OBJECT_TYPES:
            attrs = ua.ObjectTypeAttributes()
            attrs.IsAbstract = decl.abstract
            nodeid = self._node(
                ua.NodeClass.ObjectType,
                sp.node(decl.supertype),
                sp.node(decl.node),
                ua.QualifiedName(decl.name, sp.ns[decl.node[0]]),
                attrs,
                ua.ObjectIds.HasSubtype,
            )
            self._members(nodeid, decl)
        for vdecl in m.VARIABLE_TYPES:
            vattrs = ua.VariableTypeAttributes()
            vattrs.DataType = sp.node(vdecl.data_type)
            vattrs.ValueRank = -1
            nodeid = self._node(
                ua.NodeClass.VariableType,
                sp.node(vdecl.supertype),
                sp.node(vdecl.node),
                ua.QualifiedName(vdecl.name, sp.ns[vdecl.node[0]]),
                vattrs,
                ua.ObjectIds.HasSubtype,
            )
            self._members(nodeid, vdecl)
        # ToolType's ToolLife holds its entries as a placeholder (each instance names its own)
        entry = m.TOOL_LIFE_ENTRY
        mt = sp.ns[m.MACHINE_TOOL]
        self.variable(
            ua.NodeId(m.TOOL_LIFE_OBJECT, mt),
            ua.NodeId(entry.node_id, mt),
            sp.qname(entry.name),
            sp.node(entry.type_definition),
            sp.node(entry.data_type),
            _default(entry.data_type),
            entry.reference,
            rule=m.OPTIONAL_PLACEHOLDER,
        )

    def _members(self, nodeid: ua.NodeId, decl, members=None) -> None:
        """The instance declarations of a declared type, each with its modelling rule and
        its own members at every depth (a CurrentState's Id and Number...)."""
        sp = self.space
        ns = sp.ns[decl.node[0]]
        for member in decl.members if members is None else members:
            rule = m.MANDATORY if member.mandatory else m.OPTIONAL
            mid = ua.NodeId(member.node_id, ns)
            if member.node_class == "Object":
                self.object(
                    nodeid,
                    mid,
                    sp.qname(member.name),
                    sp.node(member.type_definition),
                    member.reference,
                    rule=rule,
                )
            else:
                self.variable(
                    nodeid,
                    mid,
                    sp.qname(member.name),
                    sp.node(member.type_definition),
                    sp.node(member.data_type),
                    _default(member.data_type),
                    member.reference,
                    rule=rule,
                )
            if member.children:
                self._members(mid, decl, member.children)

    # ------------------------------------------------------------------ instance groups
    # The instance's nodes have string ids in the machine's namespace: the path under the
    # machine (`mill1.Monitoring.Channel1.ChannelState`), which is also the updater's key.

    def child_object(
        self,
        parent: ua.NodeId,
        key: str,
        name: m.Name,
        typedef: m.NodeRef,
        ref: int = m.HAS_COMPONENT,
        notifier: bool = False,
    ) -> ua.NodeId:
        sp = self.space
        return self.object(
            parent, ua.NodeId(key, sp.machine_ns), sp.qname(name), sp.node(typedef), ref, notifier
        )

    def value(
        self,
        parent: ua.NodeId,
        key: str,
        name: m.Name,
        data_type: m.NodeRef,
        value,
        *,
        prop: bool = False,
        typedef: m.NodeRef | None = None,
    ) -> ua.NodeId:
        """A live (or fixed) variable; its key is how the updater finds it."""
        sp = self.space
        vtype = VARIANT_OF.get(data_type, ua.VariantType.Int32)  # enumerations are Int32
        td = typedef or (m.PROPERTY if prop else m.BASE_DATA_VARIABLE)
        nodeid = ua.NodeId(key, sp.machine_ns)
        self.variable(
            parent,
            nodeid,
            sp.qname(name),
            sp.node(td),
            sp.node(data_type),
            ua.Variant(_coerce(value, vtype), vtype),
            m.HAS_PROPERTY if prop else m.HAS_COMPONENT,
        )
        sp.variables[key] = (nodeid, vtype)
        if td == m.ANALOG_UNIT_RANGE:  # its two mandatory properties
            for prop_name, dt, prop_value in (
                ("EURange", ua.ObjectIds.Range, ua.Variant(ua.Range(0.0, 200.0))),
                ("EngineeringUnits", ua.ObjectIds.EUInformation, ua.Variant(PERCENT)),
            ):
                self.variable(
                    nodeid,
                    ua.NodeId(f"{key}.{prop_name}", sp.machine_ns),
                    ua.QualifiedName(prop_name, 0),
                    ua.NodeId(ua.ObjectIds.PropertyType),
                    ua.NodeId(dt),
                    prop_value,
                    m.HAS_PROPERTY,
                )
        return nodeid

    def values(self, parent: ua.NodeId, prefix: str, items, *, prop: bool = False) -> None:
        """Several variables under one node: (browse name, data type, initial value) each,
        keyed `<prefix>.<name>`."""
        for name, data_type, value in items:
            self.value(parent, f"{prefix}.{name[1]}", name, data_type, value, prop=prop)

    def tool_life(
        self,
        parent: ua.NodeId,
        key: str,
        name: m.Name,
        data_type: m.NodeRef,
        indication: str,
        unit: ua.EUInformation,
        limit: float | None,
    ) -> ua.NodeId:
        """A tool life counter (OPC 40501 ToolLifeType) counting up from zero, with its
        mandatory properties and, when the tool has one, its LimitValue."""
        sp = self.space
        node = self.value(parent, key, name, data_type, None, typedef=m.TOOL_LIFE.node)
        mt = m.MACHINE_TOOL
        self.variable(
            node,
            ua.NodeId(f"{key}.EngineeringUnits", sp.machine_ns),
            sp.qname((mt, "EngineeringUnits")),
            ua.NodeId(ua.ObjectIds.PropertyType),
            ua.NodeId(ua.ObjectIds.EUInformation),
            ua.Variant(unit),
            m.HAS_PROPERTY,
        )
        fields = m.TOOL_LIFE_INDICATION.fields
        self.value(
            node,
            f"{key}.Indication",
            (mt, "Indication"),
            m.TOOL_LIFE_INDICATION.node,
            fields.index(indication),
            prop=True,
        )
        self.value(node, f"{key}.IsCountingUp", (mt, "IsCountingUp"), m.BOOLEAN, True, prop=True)
        if limit is not None:
            self.value(node, f"{key}.LimitValue", (mt, "LimitValue"), data_type, limit, prop=True)
        return node

    def override(self, parent: ua.NodeId, key: str, name: m.Name) -> ua.NodeId:
        """An override in percent (AnalogUnitRange, 0..200 %), as 40501 declares them."""
        return self.value(parent, key, name, m.DOUBLE, 100.0, typedef=m.ANALOG_UNIT_RANGE)

    def state(
        self,
        parent: ua.NodeId,
        prefix: str,
        typedef: m.NodeRef,
        initial: str,
        name: m.Name = (m.MACHINE_TOOL, "State"),
    ) -> None:
        """A state machine (40501's `State`, 40001's MachineryItemState...) with its
        CurrentState (the state's display name) and CurrentState's Id (the node of the
        state in the state machine's type) and Number (its StateNumber); `initial` "" for
        none yet (a null Id, Number 0)."""
        key = f"{prefix}.{name[1]}"
        st = self.child_object(parent, key, name, typedef)
        current = self.value(
            st,
            f"{key}.CurrentState",
            (m.UA, "CurrentState"),
            m.LOCALIZED_TEXT,
            initial,
            typedef=m.FINITE_STATE_VARIABLE,
        )
        state_node, number = m.STATES_OF[typedef].get(initial, (None, 0))
        ident = self.space.node(state_node) if state_node is not None else ua.NodeId()
        q = f"{key}.CurrentState"
        self.value(current, f"{q}.Id", (m.UA, "Id"), m.NODE_ID, ident, prop=True)
        self.value(current, f"{q}.Number", (m.UA, "Number"), m.UINT32, number, prop=True)

    def ordered(
        self,
        parent: ua.NodeId,
        key: str,
        name: m.Name,
        typedef: m.NodeRef,
        number: int,
        number_type: m.NodeRef = m.UINT16,
    ) -> ua.NodeId:
        """An entry of an ordered list (HasOrderedComponent) with its NumberInList."""
        node = self.child_object(parent, key, name, typedef, ref=m.HAS_ORDERED_COMPONENT)
        self.value(
            node, f"{key}.NumberInList", (m.UA, "NumberInList"), number_type, number, prop=True
        )
        return node

    def method(self, parent: ua.NodeId, key: str, name: m.Name, callback) -> ua.NodeId:
        """A method without arguments; `callback(parent)` runs on the server's loop."""
        sp = self.space
        attrs = ua.MethodAttributes()
        attrs.Executable = attrs.UserExecutable = True
        nodeid = self._node(
            ua.NodeClass.Method,
            parent,
            ua.NodeId(key, sp.machine_ns),
            sp.qname(name),
            attrs,
            m.HAS_COMPONENT,
        )
        self.server.link_method(self.server.get_node(nodeid), callback)
        return nodeid


def _default(data_type: m.NodeRef | None) -> ua.Variant:
    if data_type == m.RANGE:
        return ua.Variant(ua.Range(), ua.VariantType.ExtensionObject)
    vtype = VARIANT_OF.get(data_type, ua.VariantType.Int32) if data_type else ua.VariantType.Null
    return ua.Variant(_coerce(None, vtype), vtype)


def _coerce(value, vtype: ua.VariantType):
    if value is not None:
        if vtype == ua.VariantType.LocalizedText and isinstance(value, str):
            return ua.LocalizedText(value)
        return value
    return {
        ua.VariantType.Boolean: False,
        ua.VariantType.String: "",
        ua.VariantType.LocalizedText: ua.LocalizedText(""),
        ua.VariantType.Double: 0.0,
        ua.VariantType.NodeId: ua.NodeId(),
        ua.VariantType.ExtensionObject: ua.EUInformation(),  # the one extension object used
    }.get(vtype, 0 if vtype != ua.VariantType.Null else None)
