"""The PLC's own configuration section (`plc`), used without the NC: the package validates
it alone; the machine loader only places its problems under `machines.<NAME>.plc`."""

from __future__ import annotations

import pytest
from pydantic import ValidationError

from plc.config import PlcConfig
from plc.m_functions import STANDARD_EXTRA


def test_a_valid_section_has_no_problems():
    section = PlcConfig.model_validate(
        {"m_codes": {31: {"ms": 500, "sets": "Conveyor"}}, "modbus_write_allow": "coil:0-15"}
    )
    assert section.problems() == []
    assert section.nc_m_codes == STANDARD_EXTRA | {31}
    assert [f.code for f in section.m_functions] == [31]


def test_no_table_hands_every_code_to_the_plc():
    assert PlcConfig().nc_m_codes is None
    assert PlcConfig().problems() == []


@pytest.mark.parametrize(
    ("section", "path", "reason"),
    [
        ({"m_codes": {3: {"ms": 10}}}, ("m_codes", "3"), "M3 is handled by the NC"),
        ({"modbus_write_allow": "hr:5-x"}, ("modbus_write_allow",), ""),
    ],
)
def test_problems_name_the_key_below_the_section(section, path, reason):
    ((where, why),) = PlcConfig.model_validate(section).problems()
    assert where == path and why.startswith(reason)


def test_the_section_is_strict():
    with pytest.raises(ValidationError):
        PlcConfig.model_validate({"period_ms": "10"})
