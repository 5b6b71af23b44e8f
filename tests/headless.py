"""Headless Debian Chromium for the browser tests, driven by Playwright (never a downloaded browser).

``scripts/install_browser.sh`` installs ``/usr/bin/chromium``; where it or Playwright is missing
the test that asks for the browser is skipped with the reason.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

import pytest

CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--enable-unsafe-swiftshader",
]


def browser_missing() -> str | None:
    """Why no browser can be started here, or None."""
    if not CHROMIUM.exists():
        return f"{CHROMIUM} is not installed (scripts/install_browser.sh installs it)"
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        return "playwright is not installed (pip install playwright; no browser download needed)"
    return None


@contextmanager
def launched(extra_args: Sequence[str] = ()) -> Iterator:
    """A started headless Chromium (closed on exit); skips the test when none can start."""
    reason = browser_missing()
    if reason:
        pytest.skip(reason)
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        browser = p.chromium.launch(
            executable_path=str(CHROMIUM), args=[*CHROMIUM_ARGS, *extra_args], headless=True
        )
        try:
            yield browser
        finally:
            browser.close()
