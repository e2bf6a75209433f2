#!/usr/bin/env python3
"""Run a simulated fleet on one machine: a Mosquitto broker, N vehicle-side gcsd instances and
one ground-side gcsd (QGroundControl finds it through UDP 14550, MAVProxy and scripts use
udpout:127.0.0.1:14551; both see every vehicle).

    python sitl/fleet/run.py                          # broker + 2 x 50 copters + ground side
    python sitl/fleet/run.py --instances 4 --per-instance 60
    python sitl/fleet/run.py --no-broker --no-ground --broker mqtt://10.0.0.5:1883 --first-sysid 101
                                                      # this machine adds vehicles 101.. to a shared broker

Instance k (0-based) runs `--per-instance` copters with sysids first + k * per_instance onwards,
built from vehicles.yaml (only vehicle.sysid/count, state_dir and the broker change); the ground
side is ground.yaml. Configurations go to sitl-state/fleet/run/, each instance keeps its state in
sitl-state/fleet/. Ctrl-C (or SIGTERM) stops everything cleanly: gcsd instances first (SIGTERM),
the broker last. A MAVLink network has 8-bit system ids, so one topic holds at most 254 vehicles
(255 is the usual ground-station id); a larger fleet is several topics, each with its own
ground side (README.md here).
"""

from __future__ import annotations

import argparse
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import yaml

HERE = Path(__file__).resolve().parent
MAX_SYSID = 254


def parse_args(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--instances", type=int, default=2, help="vehicle-side gcsd processes (default 2)")
    p.add_argument("--per-instance", type=int, default=50, help="copters per process (1..250, default 50)")
    p.add_argument("--first-sysid", type=int, default=1, help="sysid of the first vehicle (default 1)")
    p.add_argument("--broker", default="mqtt://127.0.0.1:1883", help="broker URL for every instance")
    p.add_argument("--topic", default="gcsd/fleet1", help="topic prefix (one MAVLink network)")
    p.add_argument("--no-broker", action="store_true", help="use a broker that is already running")
    p.add_argument("--no-ground", action="store_true", help="start no ground-side instance")
    p.add_argument("--state", default="sitl-state/fleet", help="state and generated configurations")
    args = p.parse_args(argv)
    last = args.first_sysid + args.instances * args.per_instance - 1
    if not 1 <= args.per_instance <= 250 or args.instances < 1 or args.first_sysid < 1 or last > MAX_SYSID:
        p.error(f"vehicles {args.first_sysid}..{last}: sysids must stay within 1..{MAX_SYSID} "
                "(one topic is one MAVLink network); use another --topic for more")
    return args


def instance_configs(args) -> list[tuple[str, dict]]:
    state = Path(args.state).resolve()
    vehicle = yaml.safe_load((HERE / "vehicles.yaml").read_text())
    ground = yaml.safe_load((HERE / "ground.yaml").read_text())
    out = []
    for k in range(args.instances):
        conf = yaml.safe_load(yaml.safe_dump(vehicle))
        conf["vehicle"].update(sysid=args.first_sysid + k * args.per_instance, count=args.per_instance)
        conf["state_dir"] = str(state / f"vehicles-{conf['vehicle']['sysid']}")
        [fleet] = [c for c in conf["channels"] if c["type"] == "mqtt"]
        fleet.update(broker=args.broker, topic=args.topic)
        out.append((f"vehicles-{k + 1}", conf))
    if not args.no_ground:
        ground["state_dir"] = str(state / "ground")
        [fleet] = [c for c in ground["channels"] if c["type"] == "mqtt"]
        fleet.update(broker=args.broker, topic=args.topic)
        out.append(("ground", ground))
    return out


def main(argv=None) -> int:
    args = parse_args(argv)
    run_dir = Path(args.state) / "run"
    run_dir.mkdir(parents=True, exist_ok=True)
    procs: list[tuple[str, subprocess.Popen]] = []
    broker = None
    if not args.no_broker:
        mosquitto = shutil.which("mosquitto") or shutil.which("mosquitto", path="/usr/sbin")
        if mosquitto is None:
            print("mosquitto is not installed: apt-get install mosquitto (or --no-broker --broker URL)",
                  file=sys.stderr)
            return 1
        broker = subprocess.Popen([mosquitto, "-c", str(HERE / "mosquitto.conf")], start_new_session=True)
        time.sleep(0.5)
        if broker.poll() is not None:
            print("mosquitto did not start (is port 1883 already in use? then --no-broker)", file=sys.stderr)
            return 1
    for name, conf in instance_configs(args):
        path = run_dir / f"{name}.yaml"
        path.write_text(yaml.safe_dump(conf, sort_keys=False))
        # own session: Ctrl-C reaches this script only, which stops each instance once, cleanly
        procs.append((name, subprocess.Popen([sys.executable, "-m", "gcsd", "run", "-c", str(path)],
                                             start_new_session=True)))
        sysids = conf["vehicle"]["sysid"]
        print(f"started {name}: {path} (sysid {sysids}, count {conf['vehicle'].get('count', 1)})", file=sys.stderr)
    if not args.no_ground:
        print("ground stations: QGroundControl finds the fleet by itself (broadcast to UDP 14550); "
              "mavproxy.py --master=udpout:127.0.0.1:14551", file=sys.stderr)
    stop = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    try:
        while not stop and all(p.poll() is None for _, p in procs):
            time.sleep(0.5)
    except KeyboardInterrupt:
        pass
    for name, p in procs:
        if p.poll() is not None:
            print(f"{name} exited with {p.returncode}", file=sys.stderr)
        else:
            p.terminate()
    for _, p in procs:
        try:
            p.wait(10)
        except subprocess.TimeoutExpired:
            p.kill()
    if broker is not None:
        broker.terminate()
        broker.wait(5)
    return 0


if __name__ == "__main__":
    sys.exit(main())
