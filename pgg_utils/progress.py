"""The one progress display: training steps, sweep cells and launcher runs."""

import sys
import time


def format_duration(seconds: float) -> str:
    """`1h05m` from an hour on, `4m07s` below it."""
    seconds = int(seconds)
    return (
        f"{seconds // 3600}h{seconds % 3600 // 60:02d}m" if seconds >= 3600 else f"{seconds // 60}m{seconds % 60:02d}s"
    )


class Progress:
    """`done/total unit`, what the caller adds, and the ETA at this process's rate: a live bar (rich)
    when `stream` is a terminal, else a plain line at most every `interval` seconds (0: at every
    update), for the logs of the launcher and of Slurm."""

    def __init__(self, label: str, total: int, done: int = 0, unit: str = "", interval: float = 30.0, stream=None):
        self.label, self.total, self.first, self.unit, self.interval = label, total, done, unit, interval
        self.stream = stream or sys.stdout
        self.start = time.time()
        self.last_line = -float("inf") if interval == 0 else self.start
        self.bar = None
        if self.stream.isatty():
            from rich.progress import BarColumn, Progress, TaskProgressColumn, TextColumn

            self.bar = Progress(TextColumn(label), BarColumn(), TaskProgressColumn(), TextColumn("{task.fields[line]}"))
            self.task = self.bar.add_task("", total=total, completed=done, line="")
            self.bar.start()

    def rate(self, done: int) -> float:
        """Units per second in this process so far."""
        return (done - self.first) / max(time.time() - self.start, 1e-9)

    def line(self, done: int, details: str = "") -> str:
        rate = self.rate(done)
        eta = (
            format_duration((self.total - done) / rate) if rate > 0 else ("0m00s" if done >= self.total else "unknown")
        )
        unit = f" {self.unit}" if self.unit else ""
        return f"{done:,}/{self.total:,}{unit}  {details + '  ' if details else ''}ETA {eta}"

    def update(self, done: int, details: str = "") -> None:
        if self.bar is not None:
            self.bar.update(self.task, completed=done, line=self.line(done, details))
            return
        now = time.time()
        if now - self.last_line >= self.interval:  # the line is formatted only when it is printed
            self.last_line = now
            # One write, line and newline together: print's two writes let a Ctrl-C between them leave the
            # line open, and the interrupt's own line would then continue it.
            self.stream.write(f"{self.label}: {self.line(done, details)}\n")
            self.stream.flush()

    def close(self) -> None:
        if self.bar is not None:
            self.bar.stop()
