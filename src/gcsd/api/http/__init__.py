"""gcsd's HTTP and WebSocket API (SPEC.md "HTTP and WebSocket API"): mavlink2rest's routes and
JSON (mavjson, tree), gcsd's own routes, a live status page, all on the daemon's event loop."""
