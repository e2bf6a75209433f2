"""Where a routed frame's time goes, per component, for one or more revisions of gcsd: bench/route_cost.py
(Channel.receive -> routing -> the peer's writer, in process, no sockets) sampled by py-spy, its
samples split by the component they fall in, and scaled to route_cost's own microseconds per frame
(measured in a run of its own: the sampler slows the process it samples).

Run: ``python -m bench.route_split [REV ...]`` (default: HEAD; about 40 s a revision). Needs py-spy
(``pip install py-spy``). Each REV is exported with `git archive` (gcsd.wire._speedups built in the
export when the revision has it, as ``pip install -e .`` would: routers.export_gcsd_rev).

Components, by the innermost gcsd function of a sample (py-spy --native: the C functions of
gcsd.wire._speedups have frames of their own): parse (codec: FrameParser.feed and what it calls, C
included), loop protection and dedup (dedup.py), the HTTP API's tap (http/), the routing
decision (router.py), the outbox and the peer's writer (outbox.py), and the rest of the receive
path (channel.py Channel.receive, gcs.py GCS.on_frame: attribute reads, calls, the error boundary).
"""

from __future__ import annotations

import collections
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from bench.routers import export_gcsd_rev

REPO = Path(__file__).resolve().parent.parent
COMPONENTS = (
    ("loop protection (dedup)", ("gcsd/dedup.py", "rf_")),  # rf_*: its C class in _speedups.c
    ("parse", ("gcsd/codec.py", "gcsd/_speedups.c")),  # feed and its helpers in C
    ("HTTP API tap", ("gcsd/http/",)),
    ("routing decision", ("gcsd/router.py",)),
    ("outbox and writer", ("gcsd/outbox.py", "bench/route_cost.py")),
    ("receive path (channel, on_frame)", ("gcsd/channel.py", "gcsd/gcs.py")),
)


def _component(stack: list[str]) -> str | None:
    if not any("Channel.receive" in f for f in stack):
        return None  # set-up, imports: not the routed frame
    for frame in reversed(stack):
        for name, marks in COMPONENTS:
            if any(frame.startswith(m) if m.endswith("_") else m in frame for m in marks):
                return name
    return "other"


def split(src: Path, workdir: Path) -> tuple[float, dict[str, float]]:
    env = {"PYTHONPATH": str(src), "PATH": "/usr/bin:/bin"}
    raw = workdir / "samples.txt"
    spy = shutil.which("py-spy") or str(Path(sys.executable).parent / "py-spy")
    plain = subprocess.run([sys.executable, "-m", "bench.route_cost"], cwd=REPO, env=env, capture_output=True,
                           text=True, check=True)  # the total, without the sampler's own cost
    per_frame = float(re.search(r"20 routes:\s+([\d.]+) us per routed frame", plain.stdout).group(1))
    subprocess.run([spy, "record", "-r", "1000", "--native", "-f", "raw", "-o", str(raw), "--", sys.executable, "-m",
                    "bench.route_cost"], cwd=REPO, env=env, capture_output=True, text=True, check=True)
    counts: collections.Counter[str] = collections.Counter()
    for line in raw.read_text().splitlines():
        stack, _, n = line.rpartition(" ")
        name = _component(stack.split(";"))
        if name is not None:
            counts[name] += int(n)
    total = sum(counts.values())
    return per_frame, {name: per_frame * counts[name] / total for name, _ in (*COMPONENTS, ("other", ()))}


def main(argv: list[str]) -> int:
    revs = argv or ["HEAD"]
    rows = {}
    with tempfile.TemporaryDirectory(prefix="gcsd-split-") as tmp:
        for rev in revs:
            work = Path(tmp) / rev.replace("/", "_")
            src, what = export_gcsd_rev(REPO, rev, work / "export")
            rows[what] = split(src, work)
            print(f"{what}: {rows[what][0]:.2f} us per routed frame", file=sys.stderr)
    names = [name for name, _ in COMPONENTS] + ["other"]
    print("| per routed frame, in process (20 routes) | " + " | ".join(rows) + " |")
    print("|---|" + "---:|" * len(rows))
    for name in names:
        print(f"| {name} | " + " | ".join(f"{r[1][name]:.2f} µs" for r in rows.values()) + " |")
    print("| **total** (route_cost) | " + " | ".join(f"**{r[0]:.2f} µs**" for r in rows.values()) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
