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

from fcmaster.config import Config
from fcmaster.service import Service
from tests.integration.http_harness import wait_until_listening

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
    """A person's click: move there, press, hold 150 ms, release.

    On a live page a cell's new text (or the browser restoring a scroll position) can move
    the button while the pointer travels; like a person, the pointer goes where the button is
    now, and presses once it is on it.
    """
    for _ in range(20):
        box = await target.bounding_box()
        assert box is not None
        x, y = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
        await page.mouse.move(x, y)
        if await target.evaluate(_UNDER_POINTER, [x, y]):
            break
        await asyncio.sleep(0.05)
    await page.mouse.down()
    await asyncio.sleep(HUMAN_PRESS_S)
    await page.mouse.up()


_UNDER_POINTER = "(node, [x, y]) => node.contains(document.elementFromPoint(x, y))"


@asynccontextmanager
async def dashboard(
    browser: Browser, config: Config, port: int, *, demo: bool = False, fragment: str = ""
) -> AsyncIterator[tuple[Page, list[str]]]:
    """The daemon serving ``config`` and its dashboard open in a page; the page's errors.

    ``fragment`` goes after ``/#`` (``token=…`` signs the page in).
    """
    url = f"http://127.0.0.1:{port}"
    service = Service(config, demo=demo)
    task = asyncio.create_task(service.run(install_signals=False), name="test.dashboard")
    try:
        await wait_until_listening(url, timeout_s=30)
        page = await browser.new_page(viewport={"width": 1280, "height": 900})
        problems: list[str] = []
        page.on("pageerror", lambda error: problems.append(str(error)))
        await page.goto(url + "/" + (f"#{fragment}" if fragment else ""))
        yield page, problems
    finally:
        service.stop()
        async with asyncio.timeout(10):
            await task
