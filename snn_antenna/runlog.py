"""``@logged``: a study's ``run`` keeps everything it says in ``OUT/run.log`` (logfile.LogFile).

One decorator so every output folder gets its log the same way, and a study that needs
``log.expected(...)`` blocks still gets a LogFile as its ``log``.
"""
from __future__ import annotations

import functools

from .logfile import LogFile


def logged(run_study):
    @functools.wraps(run_study)
    def run(spec, out_dir, *args, log=print, **kwargs):
        if isinstance(log, LogFile):      # already kept by the caller
            return run_study(spec, out_dir, *args, log=log, **kwargs)
        with LogFile(out_dir, log) as kept:
            return run_study(spec, out_dir, *args, log=kept, **kwargs)
    return run
