"""Flat-earth geometry around a point: good to centimetres over the few kilometres a simulated
vehicle covers. Degrees in, metres and degrees out; bearings clockwise from north."""

from __future__ import annotations

import math

EARTH_RADIUS_M = 6378137.0
_M_PER_DEG = math.pi * EARTH_RADIUS_M / 180.0


def deg_e7(deg: float) -> int:
    """Degrees as MAVLink's integer degE7."""
    return round(deg * 1e7)


def ne_m(lat1: float, lon1: float, lat2: float, lon2: float) -> tuple[float, float]:
    """North and east metres from point 1 to point 2."""
    north = (lat2 - lat1) * _M_PER_DEG
    east = (lon2 - lon1) * _M_PER_DEG * math.cos(math.radians((lat1 + lat2) * 0.5))
    return north, east


def distance_m(lat1: float, lon1: float, lat2: float, lon2: float) -> float:
    north, east = ne_m(lat1, lon1, lat2, lon2)
    return math.hypot(north, east)


def bearing_deg(lat1: float, lon1: float, lat2: float, lon2: float) -> float:
    north, east = ne_m(lat1, lon1, lat2, lon2)
    return math.degrees(math.atan2(east, north)) % 360.0


def offset(lat: float, lon: float, north_m: float, east_m: float) -> tuple[float, float]:
    """The point `north_m`, `east_m` metres from (lat, lon)."""
    dlat = north_m / _M_PER_DEG
    dlon = east_m / (_M_PER_DEG * max(math.cos(math.radians(lat)), 1e-9))
    return lat + dlat, lon + dlon


def wrap_180(deg: float) -> float:
    return (deg + 180.0) % 360.0 - 180.0


def point_in_polygon(north: float, east: float, vertices: list[tuple[float, float]]) -> bool:
    """Ray casting in a local north/east frame."""
    inside = False
    n = len(vertices)
    for i in range(n):
        n1, e1 = vertices[i]
        n2, e2 = vertices[(i + 1) % n]
        if (e1 > east) != (e2 > east):
            cross_n = n1 + (east - e1) * (n2 - n1) / (e2 - e1)
            if north < cross_n:
                inside = not inside
    return inside
