"""Missions, fence and rally: one transfer machine (`transfer`: uploads; `download`: the answers
to downloads), what it takes and gives back (`effects`), three stores (`stores`), the item form
they share (`items`) and the QGC WPL 110 files they persist as (`wpl`). The service that
connects them to a vehicle node is `gcsd.vehicle.services.mission`."""

from gcsd.vehicle.mission.effects import Origin, PlanChanged, Send, Text
from gcsd.vehicle.mission.items import MissionItem
from gcsd.vehicle.mission.stores import FenceStore, MissionStore, PlanStore, RallyStore
from gcsd.vehicle.mission.transfer import MissionTransfer

__all__ = [
    "FenceStore", "MissionItem", "MissionStore", "MissionTransfer", "Origin", "PlanChanged", "PlanStore",
    "RallyStore", "Send", "Text",
]
