"""gcsd benchmarks (not tests): routing throughput and latency against MAVProxy, one vehicle's cost.

Run ``python -m bench --help``; see bench/README.md and bench/RESULTS.md.
"""
