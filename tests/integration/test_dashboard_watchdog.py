"""The dashboard's drive view shows each commanded drive's watchdog verdict, in the real demo.

Headless Chromium on the demo's simulated fleet (fcmaster/demo.yaml gives its drives every
verdict): the view of a drive names the verdict, the timeout and the action the drive
reports; a monitor-only drive says the gateway does not command it.
"""

from __future__ import annotations

import re
from collections.abc import AsyncIterator

import pytest
from playwright.async_api import Browser, expect

from fcmaster.cli import DEMO_CONFIG
from fcmaster.config import Config
from fcmaster.config import load as load_config
from fcmaster.config import parse as parse_config
from fcmaster.subcommands.daemon import with_http_listen
from tests.integration.browser_harness import chromium, chromium_marks, dashboard, press
from tests.integration.ports import free_port

pytestmark = chromium_marks()


@pytest.fixture
async def browser() -> AsyncIterator[Browser]:
    async with chromium() as browser:
        yield browser


def _demo(port: int) -> Config:
    return with_http_listen(load_config(DEMO_CONFIG), f"127.0.0.1:{port}")


async def test_the_drive_view_shows_the_watchdog_verdicts_of_the_demo(browser: Browser) -> None:
    port = free_port()
    async with dashboard(browser, _demo(port), port, demo=True) as (page, problems):
        expected = {  # in words: never a raw token such as "too_short —"
            "supply-pump-2": "Too short: normal polling or a gateway restart can trip the drive "
            "(timeout 0.1 s, action: stop and trip).",
            "supply-pump-1": "OK: the drive stops by itself if the gateway dies "
            "(timeout 2 s, action: stop).",
            "conveyor-1": "Off: the motor keeps running if the gateway dies "
            "(no timeout, action: off).",
            "mixer-1": "Cannot be judged: what the drive does cannot be told from its settings "
            "(timeout 1 s, action: select set-up 1).",
            "extractor-1": "monitor only",
        }
        for name, text in expected.items():
            row = page.locator(f'tr[data-drive="{name}"]')
            # a person reads the table first: the row shows its verdict badge (or none). The
            # audit reads in a tenth of the line's time, so a loaded machine may take seconds
            await expect(row.get_by_test_id("watchdog")).not_to_have_text(
                "watchdog –", timeout=20000
            )
            await press(page, row.get_by_test_id("open"))
            view = page.get_by_test_id("dv-watchdog")
            await expect(view).to_contain_text(text, timeout=20000)
            await expect(view).not_to_contain_text(re.compile(r"too_short|—"))
            await page.go_back()
            await expect(page.get_by_test_id("drives")).to_be_visible()
        assert problems == []


async def test_the_fleet_table_marks_every_watchdog_verdict_of_the_demo(browser: Browser) -> None:
    port = free_port()
    async with dashboard(browser, _demo(port), port, demo=True) as (page, problems):
        # what demo.yaml's comments say each drive has (each set up by its simulation)
        expected = {
            "supply-pump-1": "watchdog ok",
            "supply-pump-2": "watchdog too short",
            "cooling-fan-1": "watchdog ok",
            "mixer-1": "watchdog unknown",
            "conveyor-1": "watchdog off",
            "conveyor-2": "watchdog off",
            "conveyor-3": "watchdog ok",
        }
        for name, text in expected.items():
            badge = page.locator(f'tr[data-drive="{name}"]').get_by_test_id("watchdog")
            await expect(badge).to_have_text(text, timeout=20000)
            await expect(badge).to_be_visible()
        for name in ("cooling-fan-2", "extractor-1", "dosing-pump-1"):  # monitor only
            badge = page.locator(f'tr[data-drive="{name}"]').get_by_test_id("watchdog")
            await expect(badge).to_be_hidden()
        off = page.locator('tr[data-drive="conveyor-1"]').get_by_test_id("watchdog")
        assert "keeps running if the gateway dies" in (await off.get_attribute("title") or "")
        assert problems == []


UNPOWERED = """
buses:
  - name: hall
    port: sim://hall
    protocol: danfoss-fc
    baudrate: 115200
    parity: E
    offline_after: 2
    probe_interval_s: 0.5
    drives:
      - {{name: pump, address: 1, control: bus, nominal_frequency_hz: 50, max_frequency_hz: 50}}
      - {{name: fan, address: 2, control: bus, nominal_frequency_hz: 50, max_frequency_hz: 50}}
    simulation:
      drives:
        1: {{parameters: {{"8-03": 1.0, "8-04": 5}}}}
        2: {{parameters: {{"8-03": 1.0, "8-04": 5}}, faults: "silent_at=0-{dark_s}"}}
http:
  listen: 127.0.0.1:{port}
  anonymous: viewer
"""


async def test_a_drive_that_has_not_answered_says_so_and_shows_its_verdict_once_it_does(
    browser: Browser,
) -> None:
    port = free_port()
    dark_s = 8  # the fan is unpowered for the first seconds
    config = parse_config(UNPOWERED.format(port=port, dark_s=dark_s))
    async with dashboard(browser, config, port) as (page, problems):
        pump = page.locator('tr[data-drive="pump"]').get_by_test_id("watchdog")
        fan = page.locator('tr[data-drive="fan"]').get_by_test_id("watchdog")
        await expect(pump).to_have_text("watchdog ok", timeout=10000)
        await expect(fan).to_have_text("watchdog –")  # no verdict: not the same as one
        await press(page, page.locator('tr[data-drive="fan"]').get_by_test_id("open"))
        view = page.get_by_test_id("dv-watchdog")
        await expect(view).to_have_text(
            "not judged yet: the drive has not answered since the gateway started"
        )
        # powered up: audited when it comes online, and the view follows without a reload
        await expect(view).to_contain_text(
            "OK: the drive stops by itself if the gateway dies "
            "(timeout 1 s, action: stop and trip).",
            timeout=20000,
        )
        await page.go_back()
        await expect(fan).to_have_text("watchdog ok")
        assert problems == []
