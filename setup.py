"""The optional compiled fast path (src/gcsd/wire/_speedups.c; gcsd/speedups.py says what it replaces).

Everything else is in pyproject.toml. `optional=True`: without a C compiler the install goes on
and gcsd runs the same pure-Python code, only slower.
"""

from setuptools import Extension, setup

setup(ext_modules=[Extension("gcsd.wire._speedups", ["src/gcsd/wire/_speedups.c"], optional=True,
                             extra_compile_args=["-O2", "-Wall"])])
