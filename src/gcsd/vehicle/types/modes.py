"""ArduPilot's mode numbers and names, from pymavlink's mode maps.

The maps are dict literals in `pymavlink/mavutil.py`. Importing that module executes all of it,
which pulls in numpy (through mavexpression and quaternion): about 18 MB of resident memory and
0.1 s of start-up for a few small tables. So the tables are read from pymavlink's installed
source with `ast.literal_eval`, without executing it: the same data, never retyped, ~20 ms.
"""

from __future__ import annotations

import ast
import importlib.util
from functools import lru_cache
from pathlib import Path


@lru_cache(maxsize=1)
def _all_maps() -> dict[str, dict[int, str]]:
    spec = importlib.util.find_spec("pymavlink")
    source = (Path(spec.submodule_search_locations[0]) / "mavutil.py").read_text()
    maps: dict[str, dict[int, str]] = {}
    for node in ast.parse(source).body:
        if (
            isinstance(node, ast.Assign)
            and len(node.targets) == 1
            and isinstance(node.targets[0], ast.Name)
            and node.targets[0].id.startswith("mode_mapping_")
        ):
            try:
                maps[node.targets[0].id] = ast.literal_eval(node.value)
            except ValueError:  # a computed map (by name, by number): not a literal table
                continue
    return maps


def mode_mapping(name: str) -> dict[int, str]:
    """`mode_mapping("acm")` is pymavlink's `mavutil.mode_mapping_acm`: mode number -> name."""
    return dict(_all_maps()[f"mode_mapping_{name}"])
