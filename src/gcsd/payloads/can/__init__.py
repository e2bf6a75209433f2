"""CAN over MAVLink (ArduPilot's AP_MAVLinkCAN): `forward.CanForwarder` is the pure core
(who forwards which bus, filters, the 5 s timeout, the inbound buffer), `buses` the python-can
buses and `nodes` the simulated DroneCAN nodes on a `virtual` bus."""
