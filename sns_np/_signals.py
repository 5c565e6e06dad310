"""Deferring Ctrl-C and SIGTERM to a safe point of a long loop (private).

An optimiser step updates the parameters and the optimiser's moments in several statements. A
``KeyboardInterrupt`` raised between two of them would leave a state that mixes two steps, and
a checkpoint written from it could not be resumed exactly. Inside :class:`deferred_signals`
the first SIGINT or SIGTERM only sets :attr:`~deferred_signals.received`; the loop looks at it
between steps and stops cleanly there. A second signal interrupts at once (the user insists),
as a plain ``KeyboardInterrupt``.

Signal handlers can only be installed from the main thread; elsewhere (a Dask worker thread,
for instance) the guard does nothing and the signals keep their usual effect.
"""

from __future__ import annotations

import signal
import threading

__all__ = ["deferred_signals"]


class deferred_signals:
    """Context manager: defer SIGINT and SIGTERM until the code looks at ``received``.

    ``received`` is None, or the name of the first signal that arrived ("SIGINT",
    "SIGTERM"). The previous handlers are restored on exit.

    Examples
    --------
    >>> import os, signal
    >>> with deferred_signals() as guard:
    ...     os.kill(os.getpid(), signal.SIGTERM)    # lands here, does not stop the process
    ...     guard.received
    'SIGTERM'
    """

    _SIGNALS = ("SIGINT", "SIGTERM")

    def __init__(self):
        self.received = None
        self._saved = {}

    def _handler(self, signum, frame):
        if self.received is not None:
            raise KeyboardInterrupt        # a second signal: stop now
        self.received = signal.Signals(signum).name

    def __enter__(self):
        if threading.current_thread() is threading.main_thread():
            for name in self._SIGNALS:
                sig = getattr(signal, name, None)
                if sig is None:                                 # pragma: no cover - Windows
                    continue
                try:
                    self._saved[sig] = signal.signal(sig, self._handler)
                except (ValueError, OSError):                   # pragma: no cover
                    pass
        return self

    def __exit__(self, *exc):
        for sig, handler in self._saved.items():
            signal.signal(sig, handler)
        self._saved.clear()
        return False
