"""How the composition root adds the HTTP API (aiohttp is imported only when the API is on).

1. `channel_configs(config)`: the `http` channel's configuration when `http.address` is set,
   to build after the configured channels and before the vehicles (each makes a Link on it);
   `channel_class(config)` is LocalChannel for it (gcsd.api.http.local), Channel for the others.
2. `attach(gcs)`, once everything is built: the HttpService over the daemon (it taps every
   received frame and becomes what opening the `http` channel does), or None.
"""

from __future__ import annotations

from gcsd.api.http.local import LOCAL_TYPE, LocalChannel, local_channel_config
from gcsd.links.channel import Channel


def channel_configs(config) -> list:
    return [] if config.http.address is None else [local_channel_config()]


def channel_class(channel_config) -> type[Channel]:
    return LocalChannel if channel_config.type == LOCAL_TYPE else Channel


def attach(gcs):
    if not any(isinstance(ch, LocalChannel) for ch in gcs.channels):
        return None
    from gcsd.api.http.service import HttpService

    return HttpService.attach(gcs)
