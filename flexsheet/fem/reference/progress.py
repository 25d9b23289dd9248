"""How the offline FEM runs show their progress: the reference solves, their worker pool and the FEM experiments
log to their modules' loggers (``logging.getLogger(__name__)``, at INFO), and :func:`show_progress` prints those
lines on stdout as bare messages — on the command line (``flexsheet experiment fem``) and, prefixed
"[solver N] ", in the worker processes of :mod:`flexsheet.fem.reference.workers`."""

from __future__ import annotations

import logging
import sys

__all__ = ["PROGRESS_LOGGERS", "show_progress"]

#: the loggers (and their children) whose INFO lines are the offline FEM runs' progress
PROGRESS_LOGGERS = ("flexsheet.fem", "flexsheet.experiments.fem")


class _StdoutHandler(logging.StreamHandler):
    """A stream handler that writes to whatever ``sys.stdout`` is when a line is logged (as ``print`` does)."""

    @property
    def stream(self):
        return sys.stdout

    @stream.setter
    def stream(self, value) -> None:
        pass


def show_progress(prefix: str = "") -> None:
    """Print the INFO (and higher) lines of :data:`PROGRESS_LOGGERS` on stdout as ``prefix`` + the message, one
    flushed line each (a worker process's prefix "[solver N] " tells its lines apart). Those loggers stop
    propagating to the root logger, so a configured root does not print them twice; a second call replaces the
    first's handler (and prefix)."""
    fmt = logging.Formatter(prefix.replace("%", "%%") + "%(message)s")
    for name in PROGRESS_LOGGERS:
        lg = logging.getLogger(name)
        for h in [h for h in lg.handlers if isinstance(h, _StdoutHandler)]:
            lg.removeHandler(h)
        h = _StdoutHandler()
        h.setFormatter(fmt)
        lg.addHandler(h)
        lg.setLevel(logging.INFO)
        lg.propagate = False
