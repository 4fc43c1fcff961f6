"""The project's exceptions.

Every error a user can cause names the field, the value and what is accepted, and is raised
before any long work starts.
"""

import logging
import os
import sys
import traceback
from pathlib import Path


MAX_SHOWN = 80   # characters of a value a message shows: a 4 MB --set value is not echoed


def shown(value, limit: int = MAX_SHOWN) -> str:
    """``repr(value)`` cut to ``limit`` characters (in the middle, marked with an ellipsis)."""
    try:
        text = repr(value)
    except Exception:                       # a repr that fails is not the user's problem
        text = f"<{type(value).__name__}>"
    return _cut(text, limit)


def _cut(text: str, limit: int = MAX_SHOWN) -> str:
    """``text`` at most ``limit`` characters, cut in the middle: a path keeps its file name,
    a long value its beginning and end."""
    if len(text) <= limit:
        return text
    head = (limit - 1) // 2
    return text[:head] + "\u2026" + text[len(text) - (limit - 1 - head):]


class SpecError(ValueError):
    """A parameter, spec field or input is outside what the toolkit accepts."""

    def __init__(self, field: str, value, accepted: str):
        self.field, self.value, self.accepted = field, value, accepted
        super().__init__(f"{_cut(str(field))} = {shown(value)} is not "
                         f"accepted: {accepted}")

    def __reduce__(self):  # errors cross process boundaries (Dask workers) intact
        return type(self), (self.field, self.value, self.accepted)


class NumericalInstabilityError(ArithmeticError):
    """A simulation produced non-finite or runaway state.

    Raised during the run (Brian2 itself only warns afterwards) with the neuron, its
    parameters, the integration settings and the largest step that is known to be safe.
    """

    def __init__(self, neuron: int, params: dict, dt_ms: float, method: str,
                 t_ms: float, safe_dt_ms: float | None):
        self.neuron, self.params, self.dt_ms, self.method = neuron, params, dt_ms, method
        self.t_ms, self.safe_dt_ms = t_ms, safe_dt_ms
        pretty = ", ".join(f"{k}={v:g}" for k, v in params.items())
        hint = (f"; a dt of at most {safe_dt_ms:.4g} ms is safe for these parameters"
                if safe_dt_ms else "")
        super().__init__(
            f"neuron {neuron} ({pretty}) became non-finite or ran away at t = {t_ms:.2f} ms "
            f"with method={method!r}, dt={dt_ms:g} ms{hint}")

    def __reduce__(self):
        return type(self), (self.neuron, self.params, self.dt_ms, self.method, self.t_ms,
                            self.safe_dt_ms)


class PipelineError(RuntimeError):
    """A live run (stream, replay, closed loop) stopped because a stage of its own failed.

    Raised in place of whatever escaped a Brian2 network operation that is not already one of
    the project's errors, so the user sees which stage failed and why, never Brian2's "unexpected
    error, please report" message; the original exception is the ``__cause__``.
    """

    def __init__(self, stage: str, reason: str):
        self.stage, self.reason = stage, reason
        super().__init__(f"{stage} failed: {reason}")

    def __reduce__(self):
        return type(self), (self.stage, self.reason)


class DeviceError(RuntimeError):
    """A device or link outside the toolkit cannot be used: a serial port that is busy, lost
    for good or silent (``bridge.wire.source.PortError``). Not the user's typing, not a bug:
    one line and exit status 1."""


def check(condition: bool, field: str, value, accepted: str) -> None:
    """Raise SpecError(field, value, accepted) unless condition holds."""
    if not condition:
        raise SpecError(field, value, accepted)


def is_number(value) -> bool:
    """A finite real number: not true/false (bool is an int in Python), not a string, not
    complex, not an array."""
    import numbers

    import numpy as np

    if not isinstance(value, numbers.Real) or isinstance(value, (bool, np.bool_)):
        return False
    try:
        return bool(np.isfinite(float(value)))
    except OverflowError:                 # an int beyond any float
        return False


def is_integer(value) -> bool:
    """An integer that is not true/false (Python's and NumPy's integer types)."""
    import numbers

    import numpy as np

    return isinstance(value, numbers.Integral) and not isinstance(value, (bool, np.bool_))


def guarded(func, args, prog: str) -> int:
    """Run a command; whatever goes wrong is one line on stderr and an exit status: 2 for
    what the user gave (SpecError), 3 for a numerical instability, 130 for Ctrl-C, 1 for a
    device, a stage of a live pipeline or the file system failing, and 1 for a bug.

    Catching everything here also keeps Brian2's temporary files (``brian_debug_*``,
    ``brian_script_*``) from piling up: Brian2 keeps them only when an exception reaches its
    ``sys.excepthook``. A failure that is not the user's (a bug) names its place in the code;
    ``SNN_ANTENNA_TRACEBACK=1`` prints the whole traceback.
    """
    try:
        return func(args)
    except SpecError as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return 2
    except NumericalInstabilityError as exc:
        print(f"{prog}: numerical instability: {exc}", file=sys.stderr)
        return 3
    except KeyboardInterrupt:
        # the objects of a run cut short are deleted on the way out, and Brian2 warns about
        # each ("getting deleted, but was never included in a network") like a traceback:
        # noise after a Ctrl-C, so its logger says only errors from here on
        logging.getLogger("brian2").setLevel(logging.ERROR)
        print(f"{prog}: interrupted", file=sys.stderr)
        return 130
    except (PipelineError, DeviceError) as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:
        print(f"{prog}: error: {_cut(str(exc.strerror or exc), 200)}"
              + (f": {_cut(str(exc.filename))}" if exc.filename else ""), file=sys.stderr)
        return 1
    except Exception as exc:                            # a bug: say where, briefly
        if os.environ.get("SNN_ANTENNA_TRACEBACK"):
            traceback.print_exc()
        frame = traceback.extract_tb(exc.__traceback__)[-1]
        print(f"{prog}: internal error: {type(exc).__name__}: {exc} (at "
              f"{Path(frame.filename).name}:{frame.lineno}; SNN_ANTENNA_TRACEBACK=1 shows the "
              "traceback; please report it)", file=sys.stderr)
        return 1
