"""The terminal live view of `gcs mission run` (rich): each UAV's phase, tracking error and link
state, the formation's speed, the latest events, and an operator prompt.

Shown on stderr when it is a terminal. When stdin is a terminal too, it is switched to cbreak
mode (no echo, no line buffering; restored on close) and read without blocking at every tick:
typing `5` and Enter asks for 5 m/s at the earliest effective time, `5 @120` for mission time
120 s, `return` (a stations mission) brings the fleet home (`return @300`: from mission time
300 s), `land` lands everyone where they are.
"""

from __future__ import annotations

import math
import os
import sys
import termios
import tty
from collections import deque

from rich.console import Console, Group
from rich.live import Live
from rich.table import Table
from rich.text import Text

from gcs.drivers.base import Phase

_PHASE_STYLE = {
    Phase.FOLLOWING: "green",
    Phase.TAKING_OFF: "cyan",
    Phase.LANDING: "cyan",
    Phase.LANDED: "dim",
    Phase.HOLDING: "yellow",
    Phase.FAILED: "bold red",
}
_LEVEL_STYLE = {"error": "bold red", "fatal": "bold red", "warning": "yellow", "info": ""}


class LiveView:
    """A rich `Live` display plus non-blocking keyboard input (see the module docstring)."""

    def __init__(self, console: Console, *, read_keys: bool = True) -> None:
        self.console = console
        self._messages: deque[tuple[str, str]] = deque(maxlen=6)
        self._typed = ""
        self._lines: list[str] = []
        self._stdin_fd: int | None = None
        self._saved_tty = None
        if read_keys and sys.stdin.isatty():
            self._stdin_fd = sys.stdin.fileno()
            self._saved_tty = termios.tcgetattr(self._stdin_fd)
            tty.setcbreak(self._stdin_fd)
            os.set_blocking(self._stdin_fd, False)
        self._live = Live(console=console, auto_refresh=False, transient=False)
        self._live.start()

    @property
    def interactive(self) -> bool:
        """Whether an operator can type commands."""
        return self._stdin_fd is not None

    def update(self, run, now: float) -> None:
        self._live.update(self._render(run, now), refresh=True)

    def message(self, level: str, text: str) -> None:
        self._messages.append((level, text))

    def commands(self) -> list[str]:
        if self._stdin_fd is None:
            return []
        try:
            data = os.read(self._stdin_fd, 1024)
        except (BlockingIOError, InterruptedError):
            data = b""
        for char in data.decode(errors="ignore"):
            if char in "\r\n":
                if self._typed.strip():
                    self._lines.append(self._typed)
                self._typed = ""
            elif char in "\x7f\b":
                self._typed = self._typed[:-1]
            elif char.isprintable():
                self._typed += char
        lines, self._lines = self._lines, []
        return lines

    def close(self) -> None:
        self._live.stop()
        if self._stdin_fd is not None:
            os.set_blocking(self._stdin_fd, True)
            termios.tcsetattr(self._stdin_fd, termios.TCSADRAIN, self._saved_tty)
            self._stdin_fd = None

    def _render(self, run, now: float) -> Group:
        t = run.mission_time
        clock = "connecting" if t is None else f"t = {t:8.2f} s"
        frozen = f"  [yellow]frozen ({run.frozen_by})[/]" if run.frozen_by else ""
        aborting = "  [bold red]LANDING EVERYONE[/]" if run.aborting else ""
        stations = run.formation.stations is not None
        if not stations:
            where = ""
        elif run.returned is not None:
            where = f"  [cyan]returning (from t={run.returned.effective_s:.1f} s)[/]"
        elif run.stations_watch.holding:
            where = "  [green]on station[/]"
        else:
            where = "  outbound"
        header = Text.from_markup(
            f"[bold]{run.mission.name}[/]  {clock}  speed {run.current_speed:.1f} m/s  "
            f"x{run.options.speedup:g}{where}{frozen}{aborting}"
        )
        table = Table(expand=False)
        for name in ("UAV", "phase", "mode", "armed", "alt (m)", "track err (m)", "link"):
            table.add_column(name, justify="right")
        rho = run.mission.safety_margin
        for index, driver in enumerate(run.drivers):
            tel = driver.telemetry
            error = run.tracking_now[index]
            style = "red" if error >= rho else ("yellow" if error >= rho / 2 else "")
            silent = driver.link.silent_for(now) * run.options.speedup
            link = (
                "lost"
                if run.links.lost[index]
                else ("-" if math.isinf(silent) else f"{silent:.1f} s")
            )
            table.add_row(
                str(driver.uav_id),
                Text(driver.phase.value, style=_PHASE_STYLE.get(driver.phase, "")),
                "-" if tel.custom_mode is None else str(tel.custom_mode),
                "yes" if tel.armed else "no",
                "-" if tel.relative_altitude is None else f"{tel.relative_altitude:.1f}",
                Text("-" if math.isnan(error) else f"{error:.2f}", style=style),
                Text(link, style="bold red" if run.links.lost[index] else ""),
            )
        stats = run.safety.stats
        distances = Text(
            f"min UAV-UAV {_fmt(stats.min_uav_uav_m)} m   min UAV-obstacle "
            f"{_fmt(stats.min_uav_obstacle_m)} m   connected "
            + (
                "-"
                if stats.connected_fraction is None
                else f"{100 * stats.connected_fraction:.0f} %"
            )
        )
        events = [Text(text, style=_LEVEL_STYLE.get(level, "")) for level, text in self._messages]
        parts = [header, table, distances, *events]
        if self.interactive:
            back = " | return [@T]" if stations and run.returned is None else ""
            if stations and run.returned is None and run.stations_watch.holding:
                back += " | relieve N"
            parts.append(Text(f"speed m/s [@T]{back} | land > {self._typed}_", style="bold"))
        return Group(*parts)


def _fmt(value: float) -> str:
    return "-" if not math.isfinite(value) else f"{value:.2f}"
