"""Missions, fence and rally: one transfer machine (`transfer`), three stores (`stores`), the
item form they share (`items`) and the QGC WPL 110 files they persist as (`wpl`). The service
that connects them to a vehicle node is `gcsd.services.mission`."""

from .items import MissionItem
from .stores import FenceStore, MissionStore, PlanStore, RallyStore
from .transfer import MissionTransfer, Origin, PlanChanged, Send, Text

__all__ = [
    "FenceStore", "MissionItem", "MissionStore", "MissionTransfer", "Origin", "PlanChanged", "PlanStore",
    "RallyStore", "Send", "Text",
]
