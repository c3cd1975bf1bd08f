"""The dashboard's drive view shows each commanded drive's watchdog verdict, in the real demo.

Headless Chromium on the demo's simulated fleet (fcmaster/demo.yaml gives its drives every
verdict): the view of a drive names the verdict, the timeout and the action the drive
reports; a monitor-only drive says the gateway does not command it.
"""

from __future__ import annotations

import asyncio
import os
from collections.abc import AsyncIterator
from pathlib import Path

import pytest
from playwright.async_api import Browser, async_playwright, expect

from fcmaster.cli import DEMO_CONFIG
from fcmaster.config import load as load_config
from fcmaster.service import Service
from fcmaster.subcommands.daemon import with_http_listen
from tests.integration.http_harness import wait_until_listening
from tests.integration.ports import free_port

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--no-first-run"]

if not Path(CHROMIUM).exists():
    if os.environ.get("CI") == "true":
        raise RuntimeError(f"the dashboard tests need {CHROMIUM} (apt package chromium)")
    pytestmark = pytest.mark.skip(reason=f"needs {CHROMIUM}")


@pytest.fixture
async def browser() -> AsyncIterator[Browser]:
    async with async_playwright() as playwright:
        browser = await playwright.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        try:
            yield browser
        finally:
            await browser.close()


async def test_the_drive_view_shows_the_watchdog_verdicts_of_the_demo(browser: Browser) -> None:
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    service = Service(with_http_listen(load_config(DEMO_CONFIG), f"127.0.0.1:{port}"), demo=True)
    task = asyncio.create_task(service.run(install_signals=False), name="test.demo")
    try:
        await wait_until_listening(url, timeout_s=30)
        page = await browser.new_page(viewport={"width": 1280, "height": 900})
        problems: list[str] = []
        page.on("pageerror", lambda error: problems.append(str(error)))
        await page.goto(url + "/")
        expected = {
            "supply-pump-2": "too_short — timeout 0.1 s, action stop and trip",
            "supply-pump-1": "ok — timeout 2 s, action stop",
            "conveyor-1": "off — timeout – s, action off",
            "mixer-1": "unknown — timeout 1 s, action select set-up 1",
            "extractor-1": "monitor only",
        }
        for name, text in expected.items():
            await page.locator(f'tr[data-drive="{name}"]').get_by_test_id("open").click()
            await expect(page.get_by_test_id("dv-watchdog")).to_contain_text(text, timeout=20000)
            await page.go_back()
            await expect(page.get_by_test_id("drives")).to_be_visible()
        assert problems == []
    finally:
        service.stop()
        async with asyncio.timeout(10):
            await task
