"""Flight logs: DataFlash logs captured from a flight controller, written by the simulated
vehicle, kept in one directory and served by the MAVLink log protocol and FTP (SPEC.md
"Flight logs"). The protocol cores (capture.py, transfer.py, simlog.py, dataflash.py) are pure;
store.py does the file I/O; service.py is the thin adapter to the node."""
