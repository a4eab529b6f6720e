"""Our declared OPC UA types (cnc/faces/opcua/model.py) against the official NodeSet2 files:
same node ids, browse names, supertypes, data types, modelling rules, and every mandatory
member of each type (and of its supertypes) declared."""

from __future__ import annotations

import pytest

from cnc.faces.opcua import model as m
from tests.cnc.opcua_nodesets import nodes

HAS_SUBTYPE, HAS_TYPEDEF, HAS_RULE = 45, 40, 37
MEMBER_REFS = (m.HAS_COMPONENT, m.HAS_PROPERTY, m.HAS_ADD_IN, 49)
# Mandatory members we deliberately leave out, with the reason (checked to stay true).
NOT_SERVED = {
    # the Machinery interfaces' DefaultInstanceBrowseName has no modelling rule on instances
}


@pytest.mark.parametrize("decl", m.OBJECT_TYPES, ids=lambda d: d.name)
def test_each_declared_object_type_matches_the_nodeset(decl):
    official = nodes()[decl.node]
    assert official.node_class == "UAObjectType"
    assert official.name == (decl.node[0], decl.name)
    assert official.targets(HAS_SUBTYPE, forward=False) == [decl.supertype]
    for member in decl.members:
        found = nodes()[(decl.node[0], member.node_id)]
        assert found.name == member.name, member
        assert found.node_class == "UA" + member.node_class, member
        assert found.targets(HAS_TYPEDEF) == [member.type_definition], member
        rule = m.MANDATORY if member.mandatory else m.OPTIONAL
        assert found.targets(HAS_RULE) == [(m.UA, rule)], member
        assert decl.node in found.targets(member.reference, forward=False) or (
            decl.node in [t for r, f, t in found.refs if not f]
        ), member
        if member.data_type is not None:
            assert found.data_type == member.data_type, member


@pytest.mark.parametrize("decl", m.OBJECT_TYPES, ids=lambda d: d.name)
def test_every_mandatory_member_of_a_declared_type_is_declared(decl):
    official = nodes()[decl.node]
    declared = {x.node_id for x in decl.members}
    for ref, forward, target in official.refs:
        if not forward or ref not in MEMBER_REFS or target not in nodes():
            continue
        member = nodes()[target]
        if (m.UA, m.MANDATORY) in member.targets(HAS_RULE):
            assert target[1] in declared, f"{decl.name}: mandatory {member.name[1]} missing"


@pytest.mark.parametrize("enum", m.ENUMS, ids=lambda e: e.name)
def test_each_declared_enumeration_matches_the_nodeset(enum):
    official = nodes()[enum.node]
    assert official.node_class == "UADataType"
    assert official.name == (enum.node[0], enum.name)
    assert official.fields == tuple((name, i) for i, name in enumerate(enum.fields))


def test_the_machines_folder_is_the_machinery_entry_point():
    folder = nodes()[m.MACHINES_FOLDER]
    assert folder.name == (m.MACHINERY, "Machines")
    assert folder.targets(HAS_TYPEDEF) == [m.FOLDER]


def test_the_program_states_are_the_state_machines_states():
    for state, ident in m.PROGRAM_STATES.items():
        assert nodes()[(m.MACHINE_TOOL, ident)].name == (m.MACHINE_TOOL, state)


@pytest.mark.parametrize("decl", m.VARIABLE_TYPES, ids=lambda d: d.name)
def test_each_declared_variable_type_matches_the_nodeset(decl):
    official = nodes()[decl.node]
    assert official.node_class == "UAVariableType"
    assert official.name == (decl.node[0], decl.name)
    assert official.targets(HAS_SUBTYPE, forward=False) == [decl.supertype]
    assert official.data_type == decl.data_type
    declared = {x.node_id: x for x in decl.members}
    for member in decl.members:
        found = nodes()[(decl.node[0], member.node_id)]
        assert found.name == member.name, member
        assert found.node_class == "UAVariable", member
        assert found.targets(HAS_TYPEDEF) == [member.type_definition], member
        rule = m.MANDATORY if member.mandatory else m.OPTIONAL
        assert found.targets(HAS_RULE) == [(m.UA, rule)], member
        assert decl.node in found.targets(member.reference, forward=False), member
        assert found.data_type == member.data_type, member
    for ref, forward, target in official.refs:  # every member of the type is declared
        if forward and ref in MEMBER_REFS:
            assert target[1] in declared, f"{decl.name}: {nodes()[target].name[1]} missing"


def test_a_tools_life_entries_stand_for_the_tool_life_placeholder():
    """ToolType's ToolLife object holds ToolLifeType variables (OPC 40501-1 §11.1): the
    <ToolLifeEntry> placeholder the instance's Uses and CutTime fill."""
    life = nodes()[(m.MACHINE_TOOL, m.TOOL_LIFE_OBJECT)]
    assert life.name == (m.MACHINE_TOOL, "ToolLife")
    assert (m.MACHINE_TOOL, m.TOOL_LIFE_OBJECT) in [
        (m.MACHINE_TOOL, x.node_id) for x in m.TOOL.members if x.name[1] == "ToolLife"
    ]
    entry = m.TOOL_LIFE_ENTRY
    found = nodes()[(m.MACHINE_TOOL, entry.node_id)]
    assert found.name == entry.name
    assert found.targets(HAS_TYPEDEF) == [m.TOOL_LIFE.node] == [entry.type_definition]
    assert found.targets(HAS_RULE) == [(m.UA, m.OPTIONAL_PLACEHOLDER)]
    assert found.data_type == entry.data_type
    assert (m.MACHINE_TOOL, entry.node_id) in life.targets(entry.reference)
