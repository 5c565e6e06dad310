"""A dependency-free progress display for long loops (fitting, eigenmodes, flows).

On a terminal it redraws one line on stderr at most ``interval`` seconds apart; elsewhere (CI,
logs, notebooks without a tty) it prints a full line every ``log_every`` seconds, so long jobs
show progress without flooding the log.
"""

from __future__ import annotations

import sys
import time


def _fmt_time(s: float) -> str:
    s = max(0.0, s)
    if s < 60:
        return f"{s:4.1f}s"
    m, s = divmod(int(s), 60)
    if m < 60:
        return f"{m}m{s:02d}s"
    h, m = divmod(m, 60)
    return f"{h}h{m:02d}m"


class Progress:
    """Progress of ``total`` steps with free-form fields.

    Parameters
    ----------
    total : int
    label : str
    enabled : bool
    stream : file, default sys.stderr
    interval : float, seconds between terminal redraws
    log_every : float, seconds between lines when the stream is not a terminal
    """

    def __init__(self, total, label="", enabled=True, stream=None, interval=0.25,
                 log_every=15.0):
        self.total = max(int(total), 1)
        self.label = label
        self.enabled = bool(enabled)
        self.stream = stream if stream is not None else sys.stderr
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.interval = interval if self.tty else log_every
        self.t0 = time.perf_counter()
        self._last = -1e9
        self._drawn = False
        self._first = None  # (time, done) of the first update: the ETA leaves out warm-up

    def update(self, done, force=False, **fields):
        if not self.enabled:
            return
        now = time.perf_counter()
        if not force and now - self._last < self.interval:
            return
        self._last = now
        elapsed = now - self.t0
        frac = min(max(done / self.total, 0.0), 1.0)
        if self._first is None:
            self._first = (now, done)
        t1, d1 = self._first
        # rate from the first update on, so that compilation and set-up do not inflate it
        eta = (self.total - done) * (now - t1) / (done - d1) if done > d1 else float("nan")
        width = 20
        bar = "#" * int(round(frac * width))
        info = "  ".join(f"{k} {v}" for k, v in fields.items())
        eta_s = _fmt_time(eta) if eta == eta else "?"
        line = (f"{self.label} {done}/{self.total} [{bar:<{width}}] {info}  "
                f"{_fmt_time(elapsed)} (eta {eta_s})")
        if self.tty:
            self.stream.write("\r" + line[:160].ljust(min(len(line), 160)))
            self._drawn = True
        else:
            self.stream.write(line + "\n")
        self.stream.flush()

    def close(self, done=None, **fields):
        if not self.enabled:
            return
        if done is not None:
            self.update(done, force=True, **fields)
        if self.tty and self._drawn:
            self.stream.write("\n")
            self.stream.flush()
