"""A simulated 3-axis gimbal and the gimbal manager in front of it (gimbal protocol v2, as
ArduPilot 4.6's AP_Mount implements it): `mount.Mount` is the pure core, `params` its MNT1_*
parameters, `service` the MAVLink service that feeds it commands and messages."""
