"""The DAQmx error codes the stand-in raises (numbers as in NI-DAQmx)."""

from __future__ import annotations

from enum import IntEnum


class DAQmxErrors(IntEnum):
    CAN_NOT_PERFORM_OP_WHILE_TASK_RUNNING = -200479
    SAMP_RATE_TOO_HIGH = -200332
    SAMPLES_NOT_YET_AVAILABLE = -200284
    SAMPLES_WILL_NEVER_BE_AVAILABLE = -200278
    INVALID_DEVICE_ID = -200220
    PHYSICAL_CHAN_DOES_NOT_EXIST = -200170
    INVALID_TASK = -200088
    INVALID_ATTRIBUTE_VALUE = -200077
    UNKNOWN = -1
