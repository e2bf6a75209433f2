"""Logging: structlog, configured once at start by `setup_logging`.

Two formats. ``console`` is for people: aligned, coloured when stdout is a terminal. ``json`` is
for machines (journald, a parent process reading the daemon live): one JSON object per line on
stdout, with ``timestamp`` (ISO 8601, UTC), ``level`` and ``event``, and every line is flushed as
it is written. Events below the configured level are dropped before they are formatted. Records
from the standard library's ``logging`` (asyncio, pyserial, ...) are rendered the same way, so
the daemon writes one format.

House conventions (STYLE.md): event names are past tense and fixed (``channel_opened``,
``mission_upload_completed``), and the values go in fixed keys (``channel``, ``sysid``, ``compid``,
``msg``), bound with ``log.bind(channel=name)`` rather than formatted into the event name.
"""

from __future__ import annotations

import logging
import sys

import structlog

LEVELS = {"debug": logging.DEBUG, "info": logging.INFO, "warning": logging.WARNING, "error": logging.ERROR}
FORMATS = ("console", "json")


def setup_logging(level: str = "info", fmt: str = "console") -> None:
    if level not in LEVELS:
        raise ValueError(f"unknown log level {level!r}; expected one of {', '.join(LEVELS)}")
    if fmt not in FORMATS:
        raise ValueError(f"unknown log format {fmt!r}; expected one of {', '.join(FORMATS)}")
    timestamper = structlog.processors.TimeStamper(fmt="iso", utc=True)
    if fmt == "json":
        render = [structlog.processors.format_exc_info, structlog.processors.JSONRenderer()]
    else:
        render = [structlog.dev.ConsoleRenderer(colors=sys.stdout.isatty())]
    structlog.configure(
        processors=[
            structlog.contextvars.merge_contextvars,
            structlog.processors.add_log_level,
            timestamper,
            structlog.processors.StackInfoRenderer(),
            *render,
        ],
        wrapper_class=structlog.make_filtering_bound_logger(LEVELS[level]),
        logger_factory=structlog.PrintLoggerFactory(),  # prints to the current sys.stdout, flushed
        cache_logger_on_first_use=False,
    )
    handler = logging.StreamHandler(sys.stdout)  # flushes after every record
    handler.setFormatter(structlog.stdlib.ProcessorFormatter(
        foreign_pre_chain=[structlog.stdlib.add_log_level, structlog.stdlib.add_logger_name, timestamper],
        processors=[structlog.stdlib.ProcessorFormatter.remove_processors_meta, *render],
    ))
    root = logging.getLogger()
    root.handlers[:] = [handler]
    root.setLevel(LEVELS[level])
