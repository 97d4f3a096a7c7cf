"""Progress over a task's steps, on stderr unless ``--quiet``: a tqdm bar on a terminal; elsewhere (a file, a CI
log) a plain line now and then, so that a long task is seen to move."""

from __future__ import annotations

import sys
import time
from typing import Callable, TextIO

from tqdm import tqdm

#: seconds between two progress lines where stderr is no terminal (a log of a long run: a line every few seconds
#: at most, none for a task that ends sooner)
LINE_INTERVAL = 10.0


class Progress:
    """Steps of a long task (the studies of a run, the cases of a report); ``add`` grows the total as the task
    learns how much is left. ``enabled`` (not ``--quiet``): a bar where ``stream`` is a terminal, else a line
    ``DESC: [DONE/TOTAL] STEP (ELAPSED s)`` after a step that ends ``interval`` seconds or more after the last line
    (or the start)."""

    def __init__(self, enabled: bool, total: int, desc: str, *, stream: TextIO | None = None,
                 interval: float = LINE_INTERVAL, clock: Callable[[], float] = time.monotonic):
        self.stream = sys.stderr if stream is None else stream
        terminal = enabled and self.stream.isatty()
        self.bar = tqdm(total=total, desc=desc, unit="step", file=self.stream, leave=False) if terminal else None
        self.lines = enabled and not terminal
        self.desc, self.total, self.done = desc, total, 0
        self.interval, self.clock = interval, clock
        self.start = self.last = clock()

    def add(self, n: int) -> None:
        self.total += n
        if self.bar is not None:
            self.bar.total += n
            self.bar.refresh()

    def step(self, description: str = "") -> None:
        self.done += 1
        if self.bar is not None:
            if description:
                self.bar.set_postfix_str(description[:40], refresh=False)
            self.bar.update(1)
        elif self.lines and self.clock() - self.last >= self.interval:
            self.last = self.clock()
            line = f"{self.desc}: [{self.done}/{self.total}] {description[:80]}".rstrip()
            print(f"{line} ({self.last - self.start:.0f} s)", file=self.stream, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
