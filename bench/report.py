"""The side-by-side table the comparison benchmarks print: metric, gcsd, the peer, the ratio,
SPEC's target and whether gcsd meets it. A row is (metric, gcsd value, peer value, "hi" | "lo"
(which way is better) | None, target text, check(gcsd value) -> bool | None)."""

from __future__ import annotations

from collections.abc import Callable, Iterable

Row = tuple[str, float | None, float | None, str | None, str, Callable[[float], bool] | None]


def fmt(v: float | None) -> str:
    if v is None:
        return "n/a"
    if abs(v) >= 1000:
        return f"{v:,.0f}"
    if abs(v) >= 10:
        return f"{v:.1f}"
    return f"{v:.3f}"


def comparison_table(peer: str, rows: Iterable[Row], notes: Iterable[str] = ()) -> str:
    head = ("metric", "gcsd", peer, "gcsd/MAVSDK", "SPEC target", "gcsd meets")
    body = []
    for name, gv, mv, better, target, ok in rows:
        ratio = "n/a"
        if gv is not None and mv not in (None, 0):
            ratio = f"{gv / mv:.2f}" + {"hi": " (higher better)", "lo": " (lower better)"}.get(better, "")
        meets = "" if ok is None or gv is None else ("yes" if ok(gv) else "NO")
        body.append((name, fmt(gv), fmt(mv), ratio, target, meets))
    widths = [max(len(r[i]) for r in (head, *body)) for i in range(len(head))]

    def line(r):
        return "  ".join(c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(r, widths)))

    return "\n".join([line(head), "  ".join("-" * w for w in widths), *map(line, body), "", *notes])


# A row of the routing table: (metric, {router: value}, "hi" | "lo" | None,
# target text, check({router: value}) -> bool | None for gcsd's "meets" column).
RouterRow = tuple[str, dict[str, float | None], str | None, str, Callable[[dict], bool | None] | None]


def routers_table(labels: dict[str, str], rows: Iterable[RouterRow]) -> str:
    """One column per router in `labels` (name -> column title; gcsd first), then gcsd/<router> for
    every other router, SPEC's target and whether gcsd meets it. Rows with no value are left out."""
    others = [r for r in labels if r != "gcsd"]
    head = ("metric", *labels.values(), *(f"gcsd/{labels[r]}" for r in others), "SPEC target", "gcsd meets")
    body = []
    for name, vals, better, target, ok in rows:
        if all(vals.get(r) is None for r in labels):
            continue
        gv = vals.get("gcsd")
        ratios = []
        for r in others:
            rv = vals.get(r)
            ratios.append("n/a" if gv is None or rv in (None, 0) else
                          f"{gv / rv:.2f}" + {"hi": " (higher better)", "lo": " (lower better)"}.get(better, ""))
        verdict = None if ok is None or gv is None else ok(vals)
        meets = "" if verdict is None else ("yes" if verdict else "NO")
        body.append((name, *(fmt(vals.get(r)) for r in labels), *ratios, target, meets))
    if not body:
        return ""
    widths = [max(len(r[i]) for r in (head, *body)) for i in range(len(head))]

    def line(r):
        return "  ".join(c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(r, widths)))

    return "\n".join([line(head), "  ".join("-" * w for w in widths), *map(line, body)])


def standalone(argv: list[str], prog: str, doc: str, quick_help: str, measure: Callable, table: Callable,
               failed: Callable) -> int:
    """`python bench/NAME.py [--quick] [--keep]`: one measurement alone in a scratch directory,
    its table on stdout; exit 1 when `failed(result)`."""
    import argparse
    import shutil
    import sys
    import tempfile
    from pathlib import Path

    p = argparse.ArgumentParser(prog=f"python bench/{prog}.py", description=doc.split("\n")[0])
    p.add_argument("--quick", action="store_true", help=quick_help)
    p.add_argument("--keep", action="store_true", help="keep the temporary directory (configs, logs)")
    a = p.parse_args(argv)
    workdir = Path(tempfile.mkdtemp(prefix=f"gcsd-bench-{prog}-"))
    try:
        result = measure(workdir, a.quick)
    finally:
        if a.keep:
            print(f"kept {workdir}", file=sys.stderr, flush=True)
        else:
            shutil.rmtree(workdir, ignore_errors=True)
    print(table(result))
    return 1 if failed(result) else 0
