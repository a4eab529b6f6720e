"""The CNC controller core: NC kernel + PLC signals + axis layer, stepped per IPO cycle.

Public API (the machine shell builds against exactly this; docs/controller.md):

    Controller(config, memory, *, tools=None, work_offsets=None, machine_data=None,
               cutting_model=None, settings=None)
        .machine_data                            its cnc.machine_data.MachineData
        .put_machine_data("tools"|"offsets", doc) operator input; refused in cycle
        .cycle(CycleInputs) -> CycleOutputs      exactly once per IPO cycle; pure
        .command(name, **args)                   raises CommandRefused(reason)
        .drip_input() -> DripBuffer | None       for the DNC port's DRIP
        .policy(op, number) -> str | None        for the DNC port (READ/DELETE/PUNCH/DRIP)
        .alarms, .events, .status, .execution, .referenced, .part_count, .run_time,
        .cutting_time, .spindle_time, .max_following_error
    AxisFeedback, CycleInputs, CycleOutputs      the per-cycle contract
    IdealAxes                                    ideal axis layer (tests, `nc simulate --ideal`)
    CuttingModel, AdaptiveLoop                   ACC (spindle-load model, feed loop)
    ControllerSettings                           controller data the machine YAML lacks
"""

from cnc.controller.adaptive import AdaptiveLoop, CuttingModel
from cnc.controller.contract import (
    AXIS_COMMANDS,
    AxisFeedback,
    CommandRefused,
    CycleInputs,
    CycleOutputs,
)
from cnc.controller.core import IN_CYCLE, MODES, Controller, ControllerSettings
from cnc.controller.ideal import IdealAxes

__all__ = [
    "AXIS_COMMANDS",
    "IN_CYCLE",
    "MODES",
    "AdaptiveLoop",
    "AxisFeedback",
    "CommandRefused",
    "Controller",
    "ControllerSettings",
    "CuttingModel",
    "CycleInputs",
    "CycleOutputs",
    "IdealAxes",
]
