"""Runs into output folders as tests stage them, each through ``outputs.output_folder``: a
folder checked only (``--check``), a folder claimed for a block, and a run held open across
statements that then ends or is killed."""
from __future__ import annotations

import os
from contextlib import ExitStack, contextmanager

from snn_antenna.core import files, outputs


def checked(path, study: str, **kwargs) -> outputs.OutputFolder:
    """The first phase only, as ``--check`` takes it: refused here, or released untouched."""
    with outputs.output_folder(path, study, **kwargs) as folder:
        return folder


@contextmanager
def claimed(path, study: str, **kwargs):
    """A folder checked and claimed for the block, recorded at its end, as a run takes it."""
    with outputs.output_folder(path, study, **kwargs) as folder:
        folder.claim()
        yield folder


class Run:
    """A run's folder, claimed and held across statements: :meth:`end` records it as the run
    ending does; :meth:`kill` leaves it as a process killed at that instant would (its journal
    and lock gone with it, the manifest still saying "running")."""

    def __init__(self, path, study: str, **kwargs):
        self._stack = ExitStack()
        self.folder = self._stack.enter_context(outputs.output_folder(path, study, **kwargs))
        try:
            self.folder.claim()
        except BaseException:
            self._stack.close()
            raise

    def end(self) -> None:
        self._stack.close()

    def kill(self) -> None:
        files.close_journal(self.folder.journal)
        os.close(self.folder.lock_fd)          # the kernel releases a dead process's flock
        self.folder.journal = self.folder.lock_fd = None
        self._stack.pop_all()                  # nothing of the run's is recorded
