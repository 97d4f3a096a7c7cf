"""A progress bar over a task's steps: a tqdm bar on stderr when enabled (not ``--quiet`` and stderr a terminal),
else nothing."""

from __future__ import annotations

import sys

from tqdm import tqdm


class Progress:
    """Steps of a long task (the studies of a run, the cases of a report); ``add`` grows the total as the task
    learns how much is left."""

    def __init__(self, enabled: bool, total: int, desc: str):
        self.bar = tqdm(total=total, desc=desc, unit="step", file=sys.stderr, leave=False) if enabled else None

    def add(self, n: int) -> None:
        if self.bar is not None:
            self.bar.total += n
            self.bar.refresh()

    def step(self, description: str = "") -> None:
        if self.bar is not None:
            if description:
                self.bar.set_postfix_str(description[:40], refresh=False)
            self.bar.update(1)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
