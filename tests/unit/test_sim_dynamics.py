"""Kinematics of each vehicle type, pure: a state, a setpoint, limits, and a float clock."""

from __future__ import annotations

import itertools
import math

import pytest

from gcsd.vehicle.sim import (
    BlimpDynamics,
    Environment,
    FixedWingDynamics,
    GroundDynamics,
    Kind,
    Landed,
    Limits,
    MultirotorDynamics,
    Setpoint,
    SimulatedVehicle,
    SubmarineDynamics,
    TrackerDynamics,
    VehicleState,
)
from gcsd.vehicle.sim.geo import bearing_deg, distance_m, offset, wrap_180

HOME = (-35.363262, 149.165237, 584.0)
DT = 0.05


def state(**kw) -> VehicleState:
    s = VehicleState(lat=HOME[0], lon=HOME[1], alt_amsl_m=HOME[2], home_lat=HOME[0], home_lon=HOME[1],
                     home_alt_m=HOME[2])
    for k, v in kw.items():
        setattr(s, k, v)
    return s


def fly(dyn, s, sp, lim, seconds, watch=None):
    t = 0.0
    while t < seconds:
        dyn.step(s, sp, lim, DT)
        s.time_s += DT
        t += DT
        if watch is not None:
            watch(s)
    return s


def test_multirotor_climbs_at_its_climb_rate_and_stops_at_the_target_altitude():
    s, lim = state(armed=True), Limits(climb_ms=2.5)
    sp = Setpoint(Kind.TAKEOFF, HOME[0], HOME[1], HOME[2] + 10)
    fly(MultirotorDynamics(), s, sp, lim, 2.0)
    assert -s.vd_ms == pytest.approx(2.5, abs=0.01)
    fly(MultirotorDynamics(), s, sp, lim, 10.0)
    assert s.relative_alt_m == pytest.approx(10.0, abs=0.05)
    assert s.vd_ms == pytest.approx(0.0, abs=0.05)


def test_multirotor_reaches_a_target_without_overshooting_and_leans_no_more_than_angle_max():
    s, lim = state(armed=True, alt_amsl_m=HOME[2] + 20, landed=Landed.IN_AIR), Limits(cruise_speed_ms=8, angle_max_deg=20)
    lat, lon = offset(HOME[0], HOME[1], 100, 0)
    worst = {"lean": 0.0, "past": 0.0}

    def watch(v):
        worst["lean"] = max(worst["lean"], abs(v.pitch_rad), abs(v.roll_rad))
        north = (v.lat - HOME[0]) * 111319.5
        worst["past"] = max(worst["past"], north - 100)

    fly(MultirotorDynamics(), s, Setpoint(Kind.GOTO, lat, lon, HOME[2] + 20), lim, 40, watch)
    assert distance_m(s.lat, s.lon, lat, lon) < 0.2
    assert worst["past"] < 0.5
    assert math.degrees(worst["lean"]) <= 20.0 + 1e-6
    assert s.groundspeed_ms < 0.1


def test_multirotor_lands_at_land_speed_below_land_alt_low_and_touches_down():
    s = state(armed=True, alt_amsl_m=HOME[2] + 20, landed=Landed.IN_AIR)
    lim = Limits(descent_ms=1.5, land_speed_ms=0.5, land_alt_low_m=10)
    sp = Setpoint(Kind.LAND, HOME[0], HOME[1], HOME[2])
    fly(MultirotorDynamics(), s, sp, lim, 10.0)
    assert 0.4 < s.vd_ms <= 0.5 + 1e-6 and s.relative_alt_m < 10
    fly(MultirotorDynamics(), s, sp, lim, 40.0)
    assert s.landed == Landed.ON_GROUND and s.relative_alt_m == 0.0


def test_a_disarmed_multirotor_in_the_air_falls():
    s = state(armed=False, alt_amsl_m=HOME[2] + 30, landed=Landed.IN_AIR)
    fly(MultirotorDynamics(), s, Setpoint(Kind.HOLD, HOME[0], HOME[1], HOME[2] + 30), Limits(), 6.0)
    assert s.relative_alt_m == 0.0 and s.on_ground


def test_a_copter_holds_position_in_wind_but_a_blimp_drifts_inside_its_loiter_radius():
    env = Environment(wind_speed_ms=1.0, wind_from_deg=0.0)  # from the north: blows south
    for dyn, lim, drifts in ((MultirotorDynamics(), Limits(), False),
                             (BlimpDynamics(), Limits(max_speed_ms=1.5, loiter_radius_m=5, accel_ms2=0.3), True)):
        s = state(armed=True, alt_amsl_m=HOME[2] + 10, landed=Landed.IN_AIR)
        sim = SimulatedVehicle(dyn, env)
        sp = Setpoint(Kind.HOLD, HOME[0], HOME[1], HOME[2] + 10)
        for _ in range(int(8 / DT)):
            sim.update(s, sp, lim, DT)
        moved = distance_m(s.lat, s.lon, HOME[0], HOME[1])
        if drifts:
            assert 2.0 < moved < 8.0 and s.lat < HOME[0]  # carried south, pulled back near 5 m
        else:
            assert moved < 0.2


def test_a_plane_rolls_rotates_at_minimum_airspeed_then_climbs_out():
    s = state(armed=True)
    lim = Limits(min_airspeed_ms=9, cruise_speed_ms=15, climb_ms=5)
    sp = Setpoint(Kind.TAKEOFF, HOME[0], HOME[1], HOME[2] + 50)
    dyn = FixedWingDynamics()
    fly(dyn, s, sp, lim, 2.0)
    assert s.landed == Landed.TAKEOFF and s.relative_alt_m == 0.0 and 0 < s.airspeed_ms < 9
    fly(dyn, s, sp, lim, 30.0)
    assert s.landed == Landed.IN_AIR and s.relative_alt_m == pytest.approx(50.0, abs=2.0)


def test_a_plane_never_flies_below_its_minimum_airspeed_and_circles_at_its_loiter_radius():
    s = state(armed=True, alt_amsl_m=HOME[2] + 100, landed=Landed.IN_AIR, airspeed_ms=15)
    lim = Limits(min_airspeed_ms=9, cruise_speed_ms=15, loiter_radius_m=60, angle_max_deg=45)
    sp = Setpoint(Kind.HOLD, HOME[0], HOME[1], HOME[2] + 100, speed_ms=2.0)
    radii = []
    fly(FixedWingDynamics(), s, sp, lim, 60.0)
    fly(FixedWingDynamics(), s, sp, lim, 30.0, lambda v: radii.append(distance_m(HOME[0], HOME[1], v.lat, v.lon)))
    assert s.airspeed_ms >= 9 - 1e-6
    assert 45 < min(radii) and max(radii) < 80


def test_a_rover_drives_to_the_point_stays_on_the_ground_and_turns_no_faster_than_its_limit():
    s = state(armed=True)
    lim = Limits(cruise_speed_ms=2, accel_ms2=1, yaw_rate_dps=90, wp_radius_m=1)
    lat, lon = offset(HOME[0], HOME[1], -20, 5)  # behind it: it must turn round
    yaws = []
    fly(GroundDynamics(), s, Setpoint(Kind.GOTO, lat, lon, HOME[2]), lim, 30, lambda v: yaws.append(v.heading_deg))
    assert distance_m(s.lat, s.lon, lat, lon) < 1.0
    assert s.relative_alt_m == 0.0 and s.on_ground
    assert max(abs(wrap_180(b - a)) for a, b in itertools.pairwise(yaws)) <= 90 * DT + 1e-6


def test_a_sub_dives_but_never_rises_above_the_surface_and_floats_up_when_disarmed():
    s = state(armed=True)
    lim = Limits(cruise_speed_ms=1, climb_ms=0.5, descent_ms=0.5, accel_ms2=0.5)
    dyn = SubmarineDynamics()
    fly(dyn, s, Setpoint(Kind.GOTO, HOME[0], HOME[1], HOME[2] - 10), lim, 40)
    assert s.relative_alt_m == pytest.approx(-10, abs=0.2) and s.landed == Landed.IN_AIR
    fly(dyn, s, Setpoint(Kind.GOTO, HOME[0], HOME[1], HOME[2] + 10), lim, 40)
    assert s.relative_alt_m == 0.0
    s.alt_amsl_m = HOME[2] - 2
    s.armed = False
    fly(dyn, s, Setpoint(Kind.IDLE), lim, 15)
    assert s.relative_alt_m == 0.0


def test_a_tracker_points_at_a_location_at_its_slew_rate_without_moving():
    s = state(armed=True)
    lim = Limits(yaw_rate_dps=36, climb_ms=20, pitch_min_deg=-90, pitch_max_deg=90)
    lat, lon = offset(HOME[0], HOME[1], 0, 100)  # due east, 100 m up
    sp = Setpoint(Kind.POINT, lat, lon, HOME[2] + 100)
    fly(TrackerDynamics(), s, sp, lim, 1.0)
    assert s.heading_deg == pytest.approx(36.0, abs=1.0)
    fly(TrackerDynamics(), s, sp, lim, 5.0)
    assert s.heading_deg == pytest.approx(bearing_deg(HOME[0], HOME[1], lat, lon), abs=0.5)
    assert math.degrees(s.pitch_rad) == pytest.approx(45.0, abs=0.5)
    assert (s.lat, s.lon) == (HOME[0], HOME[1])


def test_the_battery_drains_faster_flying_than_at_rest_and_gps_follows_the_environment():
    env = Environment(gps_enabled=False)
    rest, flying = state(), state(armed=True, alt_amsl_m=HOME[2] + 10, landed=Landed.IN_AIR)
    sim = SimulatedVehicle(MultirotorDynamics(), env)
    sp = Setpoint(Kind.HOLD, HOME[0], HOME[1], HOME[2] + 10)
    for _ in range(int(60 / DT)):
        sim.update(rest, Setpoint(Kind.IDLE), Limits(), DT)
        sim.update(flying, sp, Limits(), DT)
    assert flying.consumed_mah > 10 * rest.consumed_mah > 0
    assert flying.gps_fix_type < 3 and flying.satellites == 0
