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


def _check_member(parent: tuple[str, int], member: m.Member, ns: str, path: str) -> None:
    """One declared member against the nodeset's, and its own members at every depth."""
    found = nodes()[(ns, member.node_id)]
    assert found.name == member.name, path
    assert found.node_class == "UA" + member.node_class, path
    assert found.targets(HAS_TYPEDEF) == [member.type_definition], path
    rule = m.MANDATORY if member.mandatory else m.OPTIONAL
    assert found.targets(HAS_RULE) == [(m.UA, rule)], path
    assert parent in found.targets(member.reference, forward=False) or (
        parent in [t for r, f, t in found.refs if not f]
    ), path
    if member.data_type is not None:
        assert found.data_type == member.data_type, path
    _check_mandatory(found, member.children, ns, path)


def _check_mandatory(official, declared_members, ns: str, path: str) -> None:
    """Every mandatory member the nodeset gives `official` is declared, and each declared
    member matches (recursively: a mandatory member's own mandatory members, and so on)."""
    declared = {x.node_id for x in declared_members}
    for ref, forward, target in official.refs:
        if not forward or ref not in MEMBER_REFS or target not in nodes():
            continue
        member = nodes()[target]
        if (m.UA, m.MANDATORY) in member.targets(HAS_RULE):
            assert target[1] in declared, f"{path}: mandatory {member.name[1]} missing"
    for x in declared_members:
        _check_member(official.node, x, ns, f"{path}/{x.name[1]}")


@pytest.mark.parametrize("decl", m.OBJECT_TYPES, ids=lambda d: d.name)
def test_each_declared_object_type_matches_the_nodeset(decl):
    official = nodes()[decl.node]
    assert official.node_class == "UAObjectType"
    assert official.name == (decl.node[0], decl.name)
    assert official.targets(HAS_SUBTYPE, forward=False) == [decl.supertype]
    for member in decl.members:
        _check_member(decl.node, member, decl.node[0], f"{decl.name}/{member.name[1]}")


@pytest.mark.parametrize("decl", m.OBJECT_TYPES, ids=lambda d: d.name)
def test_every_mandatory_member_of_a_declared_type_is_declared_at_every_depth(decl):
    _check_mandatory(nodes()[decl.node], decl.members, decl.node[0], decl.name)


def test_a_mandatory_member_missing_at_depth_is_caught():
    """The recursive check itself: drop the Id of a job's CurrentState and it fails."""
    job_state = next(x for x in m.PRODUCTION_JOB.members if x.name[1] == "State")
    current = job_state.children[0]
    crippled = m.Member(**{**_fields(current), "children": current.children[1:]})
    with pytest.raises(AssertionError, match="mandatory Id missing"):
        _check_member(
            (m.MACHINE_TOOL, job_state.node_id), crippled, m.MACHINE_TOOL, "State/CurrentState"
        )


def _fields(member: m.Member) -> dict:
    return {f: getattr(member, f) for f in m.Member.__dataclass_fields__}


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


@pytest.mark.parametrize(
    "typedef", list(m.STATES_OF), ids=lambda t: f"{t[0].split('/')[-2]}-{t[1]}"
)
def test_the_state_tables_are_the_state_machines_states(typedef):
    """Each state's node is a state of that state machine type (or of its supertype),
    with that StateNumber: what CurrentState's Id and Number show."""
    chain = [typedef]
    while chain[-1] in nodes() and nodes()[chain[-1]].targets(HAS_SUBTYPE, forward=False):
        chain.append(nodes()[chain[-1]].targets(HAS_SUBTYPE, forward=False)[0])
    states = m.STATES_OF[typedef]
    for state, (node, number) in states.items():
        found = nodes()[node]
        assert found.name[1] == state
        assert any(t in found.targets(m.HAS_COMPONENT, forward=False) for t in chain), state
        numbers = [
            nodes()[t] for t in found.targets(m.HAS_PROPERTY) if nodes()[t].name[1] == "StateNumber"
        ]
        assert [n.value for n in numbers] == [number], state


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
