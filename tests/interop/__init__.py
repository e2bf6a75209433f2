"""Real third-party ground stations (MAVProxy, MAVSDK) against the real gcsd daemon."""
