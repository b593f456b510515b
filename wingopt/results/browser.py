"""Open an HTML file in headless Chromium: console messages and a screenshot.

Used by the tests (and available to users) to check that a report renders without console
errors. Needs a Chromium binary (``chromium``, ``chromium-browser`` or ``google-chrome``).
"""

from __future__ import annotations

import re
import shutil
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path

__all__ = ["find_chromium", "BrowserCheck", "open_in_chromium"]

_FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--enable-logging=stderr",
    "--v=0",
]
_CONSOLE = re.compile(r":(INFO|WARNING|ERROR):CONSOLE[^\]]*\] (.*)")


def find_chromium() -> str | None:
    """Path of a Chromium-like browser, or None."""
    for name in ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable"):
        path = shutil.which(name)
        if path:
            return path
    return None


@dataclass(frozen=True)
class BrowserCheck:
    console: tuple[str, ...]
    screenshot: Path
    returncode: int


def open_in_chromium(html_file: Path, screenshot: Path, size: tuple[int, int] = (1200, 2400)) -> BrowserCheck:
    """Render ``html_file`` headless, save a screenshot, return every console message."""
    exe = find_chromium()
    if exe is None:
        raise FileNotFoundError("no chromium binary found (install Debian's 'chromium' package)")
    with tempfile.TemporaryDirectory() as profile:
        proc = subprocess.run(
            [
                exe,
                *_FLAGS,
                f"--user-data-dir={profile}",
                f"--screenshot={Path(screenshot).resolve()}",
                f"--window-size={size[0]},{size[1]}",
                Path(html_file).resolve().as_uri(),
            ],
            capture_output=True,
            text=True,
            timeout=120,
        )
    console = tuple(m.group(2) for m in map(_CONSOLE.search, proc.stderr.splitlines()) if m)
    return BrowserCheck(console, Path(screenshot), proc.returncode)
