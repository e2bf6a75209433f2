"""Message ids and MAV_RESULT values that more than one module tests for, defined once.

A radio's own reports (RADIO_STATUS, RADIO) are special on every path: they are processed
locally and never forwarded (router), accepted unsigned (signing), say nothing about the peer
that sent them (channel), do not make a channel active (ingress) and pass the sysid filter
(node). `is_radio` is that one rule.
"""

from __future__ import annotations

from pymavlink.dialects.v20 import ardupilotmega as _M

HEARTBEAT = _M.MAVLINK_MSG_ID_HEARTBEAT  # 0
SYSTEM_TIME = _M.MAVLINK_MSG_ID_SYSTEM_TIME  # 2
RADIO_STATUS = _M.MAVLINK_MSG_ID_RADIO_STATUS  # 109
RADIO = _M.MAVLINK_MSG_ID_RADIO  # 166
RADIO_IDS = frozenset({RADIO_STATUS, RADIO})

# MAV_RESULT, as command handlers return it
ACCEPTED = _M.MAV_RESULT_ACCEPTED
TEMPORARILY_REJECTED = _M.MAV_RESULT_TEMPORARILY_REJECTED
DENIED = _M.MAV_RESULT_DENIED
UNSUPPORTED = _M.MAV_RESULT_UNSUPPORTED
FAILED = _M.MAV_RESULT_FAILED
IN_PROGRESS = _M.MAV_RESULT_IN_PROGRESS


def is_radio(msgid: int) -> bool:
    """A radio's own report (RADIO_STATUS or RADIO)."""
    return msgid == RADIO_STATUS or msgid == RADIO
