"""The dashboard read by someone new to it: what a button will do, and values in words.

Headless Chromium on real simulated lines (the demo fleet, or FC, Mitsubishi and ENC lines
side by side), clicked with a person's timing: a start says the speed it will run at, Reset
is offered only where there is something to reset, a too-short watchdog says how to clear
it, and every vendor's values read in one style without a unit said twice.
"""

from __future__ import annotations

import re
from collections.abc import AsyncIterator

import pytest
from playwright.async_api import Browser, Page, expect

from fcmaster.cli import DEMO_CONFIG
from fcmaster.config import Config
from fcmaster.config import parse as parse_config
from tests.integration.browser_harness import chromium, chromium_marks, dashboard, press
from tests.integration.ports import free_port

pytestmark = chromium_marks()

OPERATOR = "operator-token-of-the-first-hour-0123"
KEYSTROKE_MS = 120
ONLINE_S = 20_000  # ms: the simulated lines come up and adopt their drives


@pytest.fixture
async def browser() -> AsyncIterator[Browser]:
    async with chromium() as browser:
        yield browser


def _demo_with_operator(port: int, text: str | None = None) -> Config:
    """The demo fleet (as shipped, or ``text``) with an operator token for the page's buttons."""
    text = re.sub(
        r"(?m)^http:\n  listen: \S+",
        "http:\n"
        f"  listen: 127.0.0.1:{port}\n"
        f"  tokens:\n    - {{name: ops, role: operator, token: {OPERATOR}}}",
        DEMO_CONFIG.read_text() if text is None else text,
    )
    return parse_config(text)


async def _start(page: Page, drive: str) -> None:
    await press(page, page.locator(f'tr[data-drive="{drive}"] button[data-action="start"]'))


async def test_a_start_says_the_speed_it_will_run_at(browser: Browser) -> None:
    port = free_port()
    config = _demo_with_operator(port)
    async with dashboard(browser, config, port, fragment=f"token={OPERATOR}") as (page, problems):
        row = page.locator('tr[data-drive="conveyor-3"]')  # found standing, reference 0
        state = row.get_by_test_id("state")
        await expect(state).to_have_text("stopped", timeout=ONLINE_S)
        # a person reads the row before clicking: its values and the watchdog's verdict
        await expect(row.get_by_test_id("watchdog")).to_have_text("watchdog ok", timeout=ONLINE_S)
        await expect(row.get_by_test_id("values")).to_contain_text("DC Link Voltage")
        dialog = page.get_by_test_id("confirm")
        detail = page.get_by_test_id("confirm-detail")
        toast = page.get_by_test_id("toast")

        # the Hz field empty: the confirmation says what the start will do
        await _start(page, "conveyor-3")
        await expect(page.locator("#confirm-text")).to_have_text("Start conveyor-3?")
        await expect(detail).to_have_text(
            "Its reference is 0 Hz: the motor will be powered but will not turn. "
            "To start at a speed, type it in Hz beside the buttons first."
        )
        await press(page, dialog.get_by_role("button", name="Confirm"))
        await expect(toast).to_contain_text("conveyor-3: start → done", timeout=15000)
        # running at a 0 reference is not shown as "at reference" beside 0.00 Hz
        await expect(state).to_contain_text("running forward")
        await expect(state).to_contain_text("at 0 Hz")
        await expect(state).not_to_contain_text("at reference")

        # a speed typed beside the buttons is the speed it starts at
        field = row.get_by_test_id("reference")
        await press(page, field)
        await field.press_sequentially("20", delay=KEYSTROKE_MS)
        await _start(page, "conveyor-3")
        await expect(detail).to_have_text(
            "It will run at 20 Hz, the speed typed beside the buttons."
        )
        await press(page, dialog.get_by_role("button", name="Confirm"))
        await expect(toast).to_contain_text("conveyor-3: start → done", timeout=15000)
        await expect(row.get_by_test_id("frequency")).to_contain_text("20.00 Hz", timeout=15000)
        await expect(state).to_contain_text("at reference")

        # and with the field emptied again, the present reference, in Hz
        await field.fill("")
        await _start(page, "conveyor-3")
        await expect(detail).to_have_text(
            "It will run at its present reference, 20.00 Hz (40.0 %)."
        )
        await press(page, dialog.get_by_role("button", name="Cancel"))
        await expect(dialog).to_be_hidden()
        assert problems == []


async def test_reset_is_offered_only_for_a_trip_and_says_how_to_clear_a_short_watchdog(
    browser: Browser,
) -> None:
    port = free_port()
    config = _demo_with_operator(port)
    async with dashboard(browser, config, port, fragment=f"token={OPERATOR}") as (page, problems):
        tripped = page.locator('tr[data-drive="supply-pump-2"]')  # its watchdog trips it
        await expect(tripped.get_by_test_id("conditions")).to_contain_text(
            "17 Control word timeout", timeout=ONLINE_S
        )
        await expect(tripped.get_by_test_id("watchdog")).to_have_text(
            "watchdog too short", timeout=ONLINE_S
        )
        reset = tripped.locator('button[data-action="reset"]')
        await expect(reset).to_be_visible()
        for name in ("supply-pump-1", "cooling-fan-1", "mixer-1", "conveyor-1", "conveyor-3"):
            row = page.locator(f'tr[data-drive="{name}"]')
            await expect(row.get_by_test_id("state")).not_to_have_text("offline")
            await expect(row.locator('button[data-action="start"]')).to_be_visible()
            await expect(row.locator('button[data-action="reset"]')).to_be_hidden()

        # Reset says why it will not hold, and what clears the trip for good
        await press(page, reset)
        detail = page.get_by_test_id("confirm-detail")
        await expect(page.locator("#confirm-text")).to_have_text("Reset supply-pump-2's alarms?")
        await expect(detail).to_contain_text(
            "Its watchdog is too short for this line: polling will trip it again."
        )
        await expect(detail).to_contain_text("8-03 Control Word Timeout Time")
        await expect(detail).to_contain_text("watchdog: {timeout_s: …}")
        await press(page, page.get_by_test_id("confirm").get_by_role("button", name="Cancel"))
        # the drive's view says it too, in words
        await press(page, tripped.get_by_test_id("open"))
        view = page.get_by_test_id("dv-watchdog")
        await expect(view).to_contain_text(
            "Too short: normal polling or a gateway restart can trip the drive"
        )
        await expect(view).to_contain_text("To clear it for good: set the drive's 8-03")
        await expect(view).not_to_contain_text("too_short")
        assert problems == []


async def test_the_demo_drive_tripped_by_its_watchdog_clears_once_the_advice_is_followed(
    browser: Browser,
) -> None:
    """What the page and demo.yaml advise for supply-pump-2: a watchdog fcmaster writes."""
    port = free_port()
    text = DEMO_CONFIG.read_text()
    short = "- {name: supply-pump-2, address: 2, control: bus, nominal_frequency_hz: 50, "
    assert short in text
    advised = text.replace(short, short + "watchdog: {timeout_s: 1}, ")
    config = _demo_with_operator(port, advised)
    async with dashboard(browser, config, port, fragment=f"token={OPERATOR}") as (page, problems):
        row = page.locator('tr[data-drive="supply-pump-2"]')
        await expect(row.get_by_test_id("watchdog")).to_have_text("watchdog ok", timeout=ONLINE_S)
        reset = row.locator('button[data-action="reset"]')
        await expect(reset).to_be_visible()  # tripped before its watchdog was rewritten
        await press(page, reset)
        await expect(page.get_by_test_id("confirm-detail")).to_be_hidden()  # nothing to warn of
        await press(page, page.get_by_test_id("confirm").get_by_role("button", name="Confirm"))
        await expect(page.get_by_test_id("toast")).to_contain_text("supply-pump-2: reset → done")
        await expect(row.get_by_test_id("conditions")).to_have_text("", timeout=10000)
        await expect(reset).to_be_hidden()
        await expect(row.get_by_test_id("state")).not_to_contain_text("fault")
        assert problems == []


THREE_VENDORS = """
buses:
  - name: fc
    port: sim://fc
    protocol: danfoss-fc
    baudrate: 115200
    drives:
      - {{name: fc-pump, address: 1,
         monitor: ["16-13", "16-14", "16-10", "16-17", "16-30", "16-34", "16-90"]}}
    simulation:
      drives:
        1: {{running_hz: 40}}
  - name: mits
    port: sim://mits
    protocol: mitsubishi
    baudrate: 115200
    drives:
      - {{name: fr-fan, address: 1}}
    simulation:
      drives:
        1: {{running_hz: 30}}
  - name: encl
    port: sim://encl
    protocol: enc
    baudrate: 38400  # the fastest ENC drives offer
    drives:
      - {{name: enc-mixer, address: 1}}
    simulation:
      drives:
        1: {{running_hz: 20}}
http:
  listen: 127.0.0.1:{port}
  anonymous: viewer
"""


async def test_values_of_every_vendor_read_in_one_style_with_each_unit_said_once(
    browser: Browser,
) -> None:
    port = free_port()
    config = parse_config(THREE_VENDORS.format(port=port))
    async with dashboard(browser, config, port) as (page, problems):
        # the tables name them "Power [kW]", "output current", "DC bus voltage"
        expected = {
            "fc-pump": [
                "Frequency", "Motor Current", "Power", "Speed", "DC Link Voltage", "Heatsink Temp.",
            ],
            "fr-fan": ["Output Frequency", "Output Current", "Output Voltage"],
            "enc-mixer": [
                "Running Frequency", "Output Current", "Output Voltage", "DC Bus Voltage",
                "Current Set Frequency", "Module Temperature",
            ],
        }  # fmt: skip
        for name, labels in expected.items():
            values = page.locator(f'tr[data-drive="{name}"]').get_by_test_id("values")
            await expect(values.locator(".vname")).to_have_text(labels, timeout=ONLINE_S)
        power = page.locator('tr[data-drive="fc-pump"] .value').nth(2)
        await expect(power).to_have_text(re.compile(r"^Power \d+\.\d\d kW$"))
        speed = page.locator('tr[data-drive="fc-pump"] .value').nth(3)
        await expect(speed).to_have_text(re.compile(r"^Speed \d+ rpm$"))
        await press(page, page.locator('tr[data-drive="fc-pump"]').get_by_test_id("open"))
        view = page.get_by_test_id("dv-values")
        await expect(view).to_contain_text("Power (16-10)")
        await expect(view).not_to_contain_text("[kW]")
        # a line's view says yes and no, not true and false
        await page.go_back()
        await press(page, page.locator('[data-bus="fc"]').get_by_test_id("open-line"))
        stats = page.get_by_test_id("lv-stats")
        await expect(stats).to_contain_text("line silentno")
        await expect(stats).not_to_contain_text(re.compile(r"\b(true|false)\b"))
        assert problems == []
