"""What the commands say to the user, through the ``logging`` module only.

The launcher and a container log their progress lines (``[launch] …``, ``container NAME: …``, a node's
restart) and the output lines of the nodes the launcher relays to the :data:`CONSOLE` logger
(``flexsheet.console.launch``, ``flexsheet.console.container``); the library's long work (a registration, an
experiment, a table build) logs its progress to its module's logger (``logging.getLogger(__name__)``) at INFO.

:func:`show_lines` is how a command shows them: each record's message on stdout (or stderr), a line each,
flushed at once (a WARNING or worse prefixed with its level), and kept from the root logger's handlers.
Elsewhere they go where the application's logging sends them (``flexsheet.runtime.testing.console_lines``
collects the console's, pytest's ``caplog`` any logger's).
"""

from __future__ import annotations

import logging
import sys

__all__ = ["CONSOLE", "LIBRARY", "console_logger", "show_lines"]

#: the logger of everything the launcher and the containers show the user
CONSOLE = "flexsheet.console"
#: the library's loggers (each module's ``logging.getLogger(__name__)``); :data:`CONSOLE` is among them
LIBRARY = "flexsheet"


class _Lines(logging.Handler):
    """Each record's formatted message alone on the current ``sys.stdout`` (or ``sys.stderr``), flushed (as
    ``print(line, flush=True)``: a write error such as a closed pipe is raised to the caller, not reported by
    logging)."""

    def __init__(self, stderr: bool = False) -> None:
        super().__init__()
        self.stderr = stderr

    def emit(self, record: logging.LogRecord) -> None:
        print(self.format(record), flush=True, file=sys.stderr if self.stderr else sys.stdout)


class _Plain(logging.Formatter):
    """``prefix`` + the message; a WARNING or worse leads with its level."""

    def __init__(self, prefix: str = "", clock: bool = False) -> None:
        super().__init__(("[%(asctime)s] " if clock else "") + prefix.replace("%", "%%") + "%(message)s",
                         datefmt="%H:%M:%S")

    def format(self, record: logging.LogRecord) -> str:
        text = super().format(record)
        return f"{record.levelname}: {text}" if record.levelno >= logging.WARNING else text


def console_logger(name: str) -> logging.Logger:
    """The console logger of ``name`` (``launch``, ``container``): a child of :data:`CONSOLE`."""
    return logging.getLogger(f"{CONSOLE}.{name}")


def show_lines(logger: str = CONSOLE, prefix: str = "", clock: bool = False, stderr: bool = False) -> None:
    """Show the INFO (and higher) records of ``logger`` and its children on stdout (``stderr``: on stderr, for
    a command whose stdout is data, e.g. ``--json``) as ``prefix`` + the message (``clock``: after the wall
    time ``[HH:MM:SS]``), and nowhere else. A second call on one logger replaces the first's handler (a worker
    process's prefix tells its lines apart)."""
    log = logging.getLogger(logger)
    for h in [h for h in log.handlers if isinstance(h, _Lines)]:
        log.removeHandler(h)
    h = _Lines(stderr)
    h.setFormatter(_Plain(prefix, clock))
    log.addHandler(h)
    log.setLevel(logging.INFO)
    log.propagate = False
