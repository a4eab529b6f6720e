"""The soft-PLC's section of a machine's configuration (`plc`): program, scan period,
watchdog, input filter, the M-code table and the Modbus write allow-list.
docs/configuration.md lists every key.

The plc package owns this section: its schema (pydantic models, strict) and its rules
across keys (`problems()`, paths relative to the section). The machine's loader
(`cnc.config`) places it under `machines.<NAME>.plc` and reports each problem with the file,
line and key path; the rule that ties the scan period to the NC's IPO cycle is the
machine's (cnc), since the PLC does not know the NC.
"""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ConfigDict, Field

from plc.m_functions import STANDARD_EXTRA, MTableError, table_from

__all__ = ["MCodeConfig", "PlcConfig", "Problem"]

#: One problem of a section: the key path below the section and the reason.
Problem = tuple[tuple[Any, ...], str]


class _Section(BaseModel):
    # as every configuration section (cnc.config.Section, which plc may not import):
    # strict, unknown keys refused, a loaded section is a value
    model_config = ConfigDict(extra="forbid", strict=True, frozen=True, allow_inf_nan=False)


class MCodeConfig(_Section):
    """One M function of the PLC's M-code table (`plc.m_codes.<M>`)."""

    ms: int = Field(
        0,
        ge=0,
        le=29_000,
        description="How long the function takes: the PLC gives the finish"
        " this long after the strobe (at least its 50 ms check delay), ms.",
    )
    text: str = Field("", description="What it does, for displays and the docs.")
    sets: str | None = Field(
        None,
        description="PLC bit the function switches on (a device: conveyor, air blast).",
    )
    clears: str | None = Field(None, description="PLC bit the function switches off.")


class PlcConfig(_Section):
    """The soft-PLC (`plc`)."""

    program: str | None = Field(
        None,
        description="Ladder program file (relative to the config file); null = the standard"
        " machine-tool program.",
    )
    period_ms: int = Field(
        10, ge=1, le=1000, description="Scan period, ms; an integer multiple of the IPO cycle."
    )
    watchdog_ms: float | None = Field(
        None, gt=0, description="Scan execution-time limit, ms; null = 10 × period."
    )
    debounce_samples: int = Field(
        0, ge=0, le=64, description="Input filter: a change counts after N equal samples (0 off)."
    )
    m_codes: dict[int, MCodeConfig] | None = Field(
        None,
        description="The M-code table: M functions the PLC handles besides the standard"
        " program's (docs/machine_plc.md), by code; the NC refuses an M code that is neither"
        " its own nor in this table at its block. null = no table: every M code the NC does"
        " not know is handed to the PLC.",
    )
    modbus_write_allow: str = Field(
        "",
        description="Modbus write allow-list (`coil:0-15,hr:1024-1100,%MW0-99`); empty ="
        " read-only.",
    )

    @property
    def m_functions(self) -> tuple:
        """The M-code table as `plc.m_functions.MFunction`s (raises MTableError)."""
        entries = {c: e.model_dump() for c, e in (self.m_codes or {}).items()}
        return table_from(entries)

    @property
    def nc_m_codes(self) -> frozenset[int] | None:
        """The M codes the NC hands to this PLC (None: no table, any code)."""
        if self.m_codes is None:
            return None
        return STANDARD_EXTRA | frozenset(self.m_codes)  # the entries: checked by problems()

    def problems(self) -> list[Problem]:
        """The rules across keys: the M-code table compiles, the allow-list parses."""
        out: list[Problem] = []
        if self.m_codes:
            try:
                _ = self.m_functions  # compiles the table: its errors name the entry
            except MTableError as exc:
                out.append((tuple(exc.where.split(".")), exc.message))
        if self.modbus_write_allow:
            # deferred: plc.modbus brings the Modbus server; a machine file is read without it
            from plc.modbus.allowlist import AllowList, AllowListError

            try:
                AllowList.parse(self.modbus_write_allow)
            except AllowListError as exc:
                out.append((("modbus_write_allow",), str(exc)))
        return out
