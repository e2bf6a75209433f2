"""Parameters: the typed store, definitions as data, .parm files."""

from gcsd.vehicle.params.defs import parameter_set, vehicle_defs
from gcsd.vehicle.params.store import (
    INT8,
    INT16,
    INT32,
    REAL32,
    ParamDef,
    ParamEntry,
    ParamStore,
    SetResult,
    as_float,
    to_type,
)

__all__ = [
    "INT8", "INT16", "INT32", "REAL32", "ParamDef", "ParamEntry", "ParamStore", "SetResult",
    "as_float", "parameter_set", "to_type", "vehicle_defs",
]
