"""The dashboard in a real browser, and a person at it: Chromium, and clicks with a real press.

Where Chromium is missing the browser tests are skipped, except under CI, where that is an
error: a test that needs a real browser never passes by quietly not running.
"""

from __future__ import annotations

import asyncio
import os
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path

import pytest
from playwright.async_api import Browser, Locator, Page, async_playwright

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = [
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
    "--disable-component-update", "--disable-sync", "--no-first-run",
]  # fmt: skip
HUMAN_PRESS_S = 0.150  # mouse down to mouse up, as a person clicks


def chromium_marks() -> list[pytest.MarkDecorator]:
    """A browser test module's marks: none with Chromium, a skip without; under CI, an error."""
    if Path(CHROMIUM).exists():
        return []
    if os.environ.get("CI") == "true":
        raise RuntimeError(f"the dashboard tests need {CHROMIUM} (apt package chromium)")
    return [pytest.mark.skip(reason=f"needs {CHROMIUM}")]


@asynccontextmanager
async def chromium() -> AsyncIterator[Browser]:
    """Headless Chromium, closed at the end."""
    async with async_playwright() as playwright:
        browser = await playwright.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        try:
            yield browser
        finally:
            await browser.close()


async def press(page: Page, target: Locator) -> None:
    """A person's click: move there, press, hold 150 ms, release."""
    box = await target.bounding_box()
    assert box is not None
    await page.mouse.move(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
    await page.mouse.down()
    await asyncio.sleep(HUMAN_PRESS_S)
    await page.mouse.up()
