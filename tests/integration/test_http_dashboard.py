"""The dashboard in headless Chromium: it loads, lists the fleet, follows the stream, and
lets an operator command a drive after confirming.

Set ``FCMASTER_SCREENSHOT=docs/dashboard.png`` to also write the README's screenshot.
"""

from __future__ import annotations

import asyncio
import os
from collections.abc import AsyncIterator
from pathlib import Path

import pytest
from playwright.async_api import Browser, ConsoleMessage, Page, async_playwright, expect

from fcmaster.bus.commands import Action
from fcmaster.bus.plan import DrivePlan, LinePlan
from tests.integration.gateway_double import FakeGateway
from tests.integration.http_harness import OPERATOR_TOKEN, http_model, serving

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = [
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
    "--disable-component-update", "--disable-sync", "--no-first-run",
]  # fmt: skip

pytestmark = pytest.mark.skipif(not Path(CHROMIUM).exists(), reason="needs /usr/bin/chromium")


@pytest.fixture
async def browser() -> AsyncIterator[Browser]:
    async with async_playwright() as playwright:
        browser = await playwright.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        try:
            yield browser
        finally:
            await browser.close()


async def _open(browser: Browser, url: str) -> tuple[Page, list[str]]:
    """A page on ``url`` and the errors it logs (CSP violations and script errors)."""
    page = await browser.new_page(viewport={"width": 1400, "height": 900})
    problems: list[str] = []
    page.on("pageerror", lambda error: problems.append(str(error)))

    def console(message: ConsoleMessage) -> None:
        if message.type == "error":
            problems.append(message.text)

    page.on("console", console)
    await page.goto(url)
    return page, problems


async def test_the_dashboard_lists_the_fleet_and_follows_changes_live(browser: Browser) -> None:
    gateway = FakeGateway()
    gateway.reply("pump-1", running=False, hz=0.0, value=("16-14", 0.0, "A"))
    async with serving(gateway, http_model(anonymous="viewer")) as adapter:
        page, problems = await _open(browser, adapter.url + "/")
        rows = page.locator("#drives tbody tr")
        await expect(rows).to_have_count(2)
        pump = page.locator('tr[data-drive="pump-1"]')
        fan = page.locator('tr[data-drive="fan-1"]')
        await expect(pump).to_contain_text("line1 · 1")
        await expect(pump.get_by_test_id("state")).to_have_text("stopped")
        await expect(fan.get_by_test_id("state")).to_have_text("offline")
        await expect(page.get_by_test_id("connection")).to_have_text("live")
        await expect(page.get_by_test_id("identity")).to_have_text("anonymous · viewer")
        await expect(page.locator('[data-bus="line1"]')).to_contain_text("up")

        gateway.reply("pump-1", running=True, hz=42.5, value=("16-14", 7.25, "A"))
        await expect(pump.get_by_test_id("frequency")).to_contain_text("42.50 Hz")
        await expect(pump.get_by_test_id("state")).to_contain_text("running forward")
        await expect(pump).to_contain_text("16-14 7.25 A")

        gateway.reply("fan-1", alarms=((14, "Earth fault"),), warnings=((1, "10 Volts low"),))
        await expect(fan.get_by_test_id("conditions")).to_contain_text("14 Earth fault")
        await expect(fan.get_by_test_id("conditions")).to_contain_text("1 10 Volts low")
        await expect(fan.get_by_test_id("state")).to_contain_text("fault")
        await expect(page.get_by_test_id("events")).to_contain_text("alarm 14 Earth fault raised")
        # a viewer sees no command buttons
        await expect(pump.locator("button")).to_have_count(0)
        assert problems == []


async def test_an_operator_commands_a_drive_only_after_confirming(browser: Browser) -> None:
    gateway = FakeGateway()
    gateway.reply("pump-1", running=True, hz=30.0)
    async with serving(gateway) as adapter:
        page, problems = await _open(browser, f"{adapter.url}/#token={OPERATOR_TOKEN}")
        await expect(page.get_by_test_id("identity")).to_have_text("ops · operator")
        assert "token" not in page.url  # taken out of the address bar
        pump = page.locator('tr[data-drive="pump-1"]')
        fan = page.locator('tr[data-drive="fan-1"]')
        await expect(fan).to_contain_text("monitor only")

        await pump.locator('button[data-action="start"]').click()
        dialog = page.get_by_test_id("confirm")
        await expect(dialog).to_contain_text("Start pump-1?")
        await dialog.get_by_role("button", name="Cancel").click()
        await expect(dialog).to_be_hidden()
        assert gateway.executed == []

        await pump.get_by_test_id("reference").fill("35.5")
        await pump.locator('button[data-action="set_reference"]').click()
        await expect(dialog).to_contain_text("Set pump-1's reference to 35.5 Hz?")
        await dialog.get_by_role("button", name="Confirm").click()
        await expect(page.get_by_test_id("toast")).to_contain_text("set_reference → done")
        ((drive, command),) = gateway.executed
        assert (drive, command.action, command.reference_pct, command.actor) == (
            "pump-1",
            Action.SET_REFERENCE,
            71.0,
            "ops",
        )
        assert problems == []


async def test_without_anonymous_reads_the_page_asks_for_a_token(browser: Browser) -> None:
    async with serving(FakeGateway()) as adapter:
        page, _ = await _open(browser, adapter.url + "/")
        await expect(page.get_by_test_id("connection")).to_have_text("no token")
        await expect(page.locator("#notice")).to_contain_text("needs a token")


FLEET = (
    LinePlan(
        name="line1",
        port="/dev/ttyUSB0",
        baudrate=115200,
        drives=(
            DrivePlan(name="supply-fan", address=1, control=True),
            DrivePlan(name="return-fan", address=2, control=True),
            DrivePlan(name="pump-1", address=3, control=True),
            DrivePlan(name="pump-2", address=4, control=True),
        ),
    ),
    LinePlan(
        name="line2",
        port="socket://10.0.4.20:4001",
        protocol="mitsubishi",
        baudrate=19200,
        drives=(
            DrivePlan(name="conveyor", address=1),
            DrivePlan(name="mixer", address=2, control=True),
        ),
    ),
)
TARGET_HZ = {"supply-fan": 42.0, "return-fan": 38.5, "pump-1": 50.0, "pump-2": 0.0,
             "conveyor": 27.5, "mixer": 33.0}  # fmt: skip


async def test_screenshot_of_a_fleet(browser: Browser, tmp_path: Path) -> None:
    target = os.environ.get("FCMASTER_SCREENSHOT")
    gateway = FakeGateway(lines=FLEET)
    for name in TARGET_HZ:
        gateway.reply(name, hz=0.0)
    for line, stats in gateway.stats.items():
        stats.requests, stats.replies, stats.timeouts, stats.noise_bytes = 48_210, 48_196, 14, 9
        stats.checksum_errors = 2 if line == "line1" else 0
        stats.busy_s, stats.up_since = 0.62 * 3600, gateway.clock.now() - 3600
        for latency in (0.0045, 0.0052, 0.0061, 0.012):
            stats.latency.observe(latency)
    async with serving(gateway, http_model(anonymous="viewer")) as adapter:
        page, problems = await _open(browser, f"{adapter.url}/#token={OPERATOR_TOKEN}")
        await expect(page.locator("#drives tbody tr")).to_have_count(6)
        steps = 24 if target else 3
        for step in range(1, steps + 1):
            share = min(1.0, step / (steps * 0.6))
            for name, hz in TARGET_HZ.items():
                ripple = 0.3 * ((step * 7 + len(name)) % 5 - 2) / 2 if share == 1.0 else 0.0
                gateway.reply(name, running=hz > 0, hz=round(hz * share + ripple * (hz > 0), 2),
                              value=("16-14", round(hz * share * 0.21, 2), "A"))  # fmt: skip
            await asyncio.sleep(0.26 if target else 0.05)
        gateway.reply("pump-2", alarms=((13, "Over current"),))
        gateway.reply("conveyor", running=True, hz=27.5, warnings=((59, "Current limit"),))
        gateway.reply("mixer", running=True, hz=33.0, value=("16-30", 565.0, "V"))
        gateway.offline("return-fan")
        await expect(page.locator('tr[data-drive="pump-2"]')).to_contain_text("Over current")
        await page.screenshot(path=target or tmp_path / "dashboard.png", full_page=True)
        assert problems == []
