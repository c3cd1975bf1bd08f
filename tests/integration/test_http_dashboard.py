"""The dashboard in headless Chromium: it loads, lists the fleet, follows the stream, and
lets an operator command a drive after confirming — with a person's timing, while the
line keeps the page busy.

Under CI (``CI=true``) a missing Chromium fails these tests instead of skipping them.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import os
import re
import time
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path

import pytest
from playwright.async_api import (
    Browser,
    ConsoleMessage,
    Page,
    expect,
)

from fcmaster.bus.commands import Action, Command, CommandResult, Outcome
from fcmaster.cli import DEMO_CONFIG
from fcmaster.config import load as load_config
from fcmaster.protocol.codec import ParameterKey, ParameterValue
from fcmaster.service import Service
from fcmaster.subcommands.daemon import with_http_listen
from tests.integration.browser_harness import chromium, chromium_marks, press
from tests.integration.gateway_double import FakeGateway
from tests.integration.http_harness import (
    OPERATOR_TOKEN,
    http_settings,
    serving,
    wait_until_listening,
)
from tests.integration.ports import free_port

pytestmark = chromium_marks()


@pytest.fixture
async def browser() -> AsyncIterator[Browser]:
    async with chromium() as browser:
        yield browser


async def _open(
    browser: Browser, url: str, width: int = 1400, height: int = 900
) -> tuple[Page, list[str]]:
    """A page on ``url`` and the errors it logs (CSP violations and script errors)."""
    page = await browser.new_page(viewport={"width": width, "height": height})
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
    async with serving(gateway, http_settings(anonymous="viewer")) as adapter:
        page, problems = await _open(browser, adapter.url + "/")
        rows = page.locator("#drives tbody tr")
        await expect(rows).to_have_count(2)
        pump = page.locator('tr[data-drive="pump-1"]')
        fan = page.locator('tr[data-drive="fan-1"]')
        await expect(pump).to_contain_text("line1 · 1")
        await expect(pump.get_by_test_id("values")).to_contain_text("Motor Current 0.00 A")
        await expect(pump.get_by_test_id("state")).to_have_text("stopped")
        await expect(fan.get_by_test_id("state")).to_have_text("offline")
        await expect(page.get_by_test_id("connection")).to_have_text("live")
        await expect(page.get_by_test_id("identity")).to_have_text("anonymous · viewer")
        await expect(page.locator('[data-bus="line1"]')).to_contain_text("up")

        gateway.reply("pump-1", running=True, hz=42.5, value=("16-14", 7.25, "A"))
        await expect(pump.get_by_test_id("frequency")).to_contain_text("42.50 Hz")
        await expect(pump.get_by_test_id("state")).to_contain_text("running forward")
        await expect(pump.get_by_test_id("values")).to_have_text("Motor Current 7.25 A")

        gateway.reply("fan-1", alarms=((14, "Earth fault"),), warnings=((1, "10 Volts low"),))
        await expect(fan.get_by_test_id("conditions")).to_contain_text("14 Earth fault")
        await expect(fan.get_by_test_id("conditions")).to_contain_text("1 10 Volts low")
        await expect(fan.get_by_test_id("state")).to_contain_text("fault")
        await expect(page.get_by_test_id("events")).to_contain_text("alarm 14 Earth fault raised")
        # a viewer sees no command buttons
        await expect(pump.locator("button[data-action]")).to_have_count(0)
        assert problems == []


async def test_a_line_card_names_its_usb_adapter_and_flags_a_slow_latency_timer(
    browser: Browser,
) -> None:
    gateway = FakeGateway()
    gateway.adapters["line1"] = {
        "device": "/dev/ttyUSB0",
        "driver": "ftdi_sio",
        "by_id": "/dev/serial/by-id/usb-FTDI_USB-RS485_Cable_FT1ABC-if00-port0",
        "by_path": None,
        "latency_ms": 16,
    }
    async with serving(gateway, http_settings(anonymous="viewer")) as adapter:
        page, problems = await _open(browser, adapter.url + "/")
        shown = page.locator('[data-bus="line1"]').get_by_test_id("adapter")
        await expect(shown).to_have_text(
            "usb-FTDI_USB-RS485_Cable_FT1ABC-if00-port0 · ftdi_sio · latency 16 ms"
        )
        await expect(shown).to_have_class(re.compile(r"\bwarn\b"))
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


async def test_a_wrong_token_is_called_wrong_and_a_new_link_applies_without_reload(
    browser: Browser,
) -> None:
    gateway = FakeGateway()
    async with serving(gateway) as adapter:
        page, problems = await _open(browser, adapter.url + "/#token=not-a-token-we-know-at-all")
        await expect(page.get_by_test_id("connection")).to_have_text("wrong token")
        await expect(page.get_by_test_id("notice")).to_contain_text("does not accept this token")
        await expect(page.get_by_test_id("notice")).not_to_contain_text("needs a token")
        await page.evaluate("window.marker = 1")  # gone if the page reloads
        await page.evaluate(f"location.hash = 'token={OPERATOR_TOKEN}'")  # a pasted link
        await expect(page.get_by_test_id("identity")).to_have_text("ops · operator")
        await expect(page.get_by_test_id("connection")).to_have_text("live")
        await expect(page.get_by_test_id("notice")).to_be_hidden()
        assert await page.evaluate("window.marker") == 1
        assert "token" not in page.url
        assert [p for p in problems if "401" not in p] == []  # the refused whoami is logged


DEMO = load_config(DEMO_CONFIG)
BUS_DRIVES = [d.name for line in DEMO.lines for d in line.drives if d.control]
KEYSTROKE_S = 0.120


@asynccontextmanager
async def busy(gateway: FakeGateway, every_s: float = 0.02) -> AsyncIterator[None]:
    """Every drive's frequency and current change every ``every_s``, as a busy line's do."""

    async def churn() -> None:
        for n in itertools.count():
            for line in gateway.plans:
                for k, drive in enumerate(line.drives):
                    hz = 20.0 + (n + k) % 30
                    gateway.reply(drive.name, running=True, hz=hz,
                                  value=("16-14", round(hz * 0.2, 2), "A"))  # fmt: skip
            await asyncio.sleep(every_s)

    task = asyncio.create_task(churn(), name="test.churn")
    try:
        yield
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task


async def test_a_held_click_on_stop_and_start_opens_the_confirmation_every_time(
    browser: Browser,
) -> None:
    gateway = FakeGateway(lines=DEMO.lines)
    async with serving(gateway) as adapter, busy(gateway):
        page, problems = await _open(browser, f"{adapter.url}/#token={OPERATOR_TOKEN}", 1024, 900)
        await expect(page.get_by_test_id("connection")).to_have_text("live")
        dialog = page.get_by_test_id("confirm")
        opened = []
        for name in BUS_DRIVES:
            row = page.locator(f'tr[data-drive="{name}"]')
            for action, question in (("stop", f"Stop {name}?"), ("start", f"Start {name}?")):
                button = row.locator(f'button[data-action="{action}"]')
                await button.scroll_into_view_if_needed()
                await press(page, button)
                await expect(dialog).to_be_visible(timeout=2000)
                opened.append(await page.locator("#confirm-text").text_content() == question)
                await dialog.get_by_role("button", name="Cancel").click()
                await expect(dialog).to_be_hidden()
        assert opened == [True] * (2 * len(BUS_DRIVES))
        assert len(BUS_DRIVES) == 7
        assert gateway.executed == []  # nothing was confirmed
        assert problems == []


async def test_typing_a_reference_keeps_the_text_and_the_focus_while_the_line_is_busy(
    browser: Browser,
) -> None:
    gateway = FakeGateway(lines=DEMO.lines)
    async with serving(gateway) as adapter, busy(gateway):
        page, problems = await _open(browser, f"{adapter.url}/#token={OPERATOR_TOKEN}", 1024, 900)
        await expect(page.get_by_test_id("connection")).to_have_text("live")
        for name in ("supply-pump-1", "conveyor-2"):
            field = page.locator(f'tr[data-drive="{name}"]').get_by_test_id("reference")
            await press(page, field)
            await field.press_sequentially("37.5", delay=KEYSTROKE_S * 1000)
            await expect(field).to_have_value("37.5")
            await expect(field).to_be_focused()
            await asyncio.sleep(0.5)  # and it stays so while updates keep coming
            await expect(field).to_have_value("37.5")
            await expect(field).to_be_focused()
            await field.press("Enter")
            await expect(page.get_by_test_id("confirm")).to_contain_text(
                f"Set {name}'s reference to 37.5 Hz?"
            )
            await page.keyboard.press("Enter")  # a second Enter cancels, never confirms
            await expect(page.get_by_test_id("confirm")).to_be_hidden()
        assert gateway.executed == []
        assert problems == []


@pytest.mark.parametrize(("width", "height"), [(1024, 768), (412, 915)], ids=["1024px", "phone"])
async def test_the_demo_fleet_fits_without_scrolling_sideways(
    browser: Browser, width: int, height: int
) -> None:
    gateway = FakeGateway(lines=DEMO.lines)
    for line in DEMO.lines:
        for drive in line.drives:
            gateway.reply(drive.name, running=True, hz=42.0, value=("16-14", 8.82, "A"))
    async with serving(gateway) as adapter:
        page, problems = await _open(
            browser, f"{adapter.url}/#token={OPERATOR_TOKEN}", width, height
        )
        rows = page.locator("#drives tbody tr")
        await expect(rows).to_have_count(10)
        await expect(page.get_by_test_id("connection")).to_have_text("live")
        overflow = await page.evaluate(
            "document.documentElement.scrollWidth - document.documentElement.clientWidth"
        )
        assert overflow <= 0
        for name in BUS_DRIVES:  # every control is on the page, not cut off at its right
            for control in ("button[data-action=stop]", "[data-testid=reference]"):
                box = await page.locator(f'tr[data-drive="{name}"] {control}').bounding_box()
                assert box is not None
                assert box["x"] >= 0
                assert box["x"] + box["width"] <= width
        assert problems == []


def _ramp_time(_drive: str, command: Command) -> CommandResult:
    """A read of 3-41 answers 5 s, as the drive would."""
    key = ParameterKey(command.parameter or "", 341)
    value = ParameterValue(parameter=key, index=0, raw=500, value=5.0, unit="s")
    return CommandResult(outcome=Outcome.DONE, value=value)


async def test_the_drive_view_shows_status_values_and_charts_with_axes(browser: Browser) -> None:
    gateway = FakeGateway(lines=DEMO.lines, respond=_ramp_time)
    async with serving(gateway) as adapter:
        for n in range(6):  # history before the page is opened
            gateway.reply("supply-pump-1", running=True, hz=40.0 + n,
                          value=("16-14", 8.0 + n / 10, "A"))  # fmt: skip
            await asyncio.sleep(0.3)
        gateway.reply("supply-pump-1", running=True, hz=45.0, warnings=((1, "10 Volts low"),))
        opened_at = time.time()
        page, problems = await _open(browser, adapter.url + "/#token=" + OPERATOR_TOKEN)
        await page.locator('tr[data-drive="supply-pump-1"]').get_by_test_id("open").click()
        view = page.get_by_test_id("drive-view")
        await expect(view).to_be_visible()
        await expect(page.get_by_test_id("drives")).to_be_hidden()
        await expect(view.get_by_test_id("dv-status")).to_contain_text("0x0E07")
        await expect(view.get_by_test_id("dv-status")).to_contain_text(
            "bus control, frequency ok, running"
        )
        await expect(view.get_by_test_id("dv-values")).to_contain_text("Motor Current (16-14)")
        await expect(view.get_by_test_id("dv-conditions")).to_contain_text(
            "warning 1: 10 Volts low"
        )
        charts = view.get_by_test_id("dv-charts")
        frequency = charts.locator('[data-series="output_frequency_hz"]')
        await expect(frequency.locator(".u-title")).to_have_text("Output frequency [Hz]")
        # uPlot draws axes, ticks and their labels on its canvas
        labels = await page.evaluate("detail.charts.map((c) => c.axes.map((a) => a.label))")
        assert labels[0] == ["time", "Hz"]
        assert ["time", "A"] in labels
        ticks = await page.evaluate("detail.charts[0].axes.map((a) => (a._values || []).length)")
        assert min(ticks) >= 2  # both axes have values written along them
        current = charts.locator('[data-series="16-14"]')
        await expect(current.locator(".u-title")).to_have_text("Motor Current [A]")
        first, points = await page.evaluate("[detail.t[0], detail.t.length]")
        assert points >= 2
        assert first < opened_at - 1.0  # the daemon's history, not only what arrived since
        gateway.reply("supply-pump-1", running=True, hz=12.0)
        await page.wait_for_function("detail.series[0].data.at(-1) === 12.0")  # drawn live too
        # a one-off read answers where it was asked, and stays out of the monitored values
        await view.get_by_label("parameter").fill("3-41")
        await view.get_by_role("button", name="Read").click()
        await expect(view.get_by_test_id("dv-read-result")).to_contain_text("3-41 = 5.00 s")
        ((drive, command),) = gateway.executed
        assert (drive, command.action, command.parameter) == ("supply-pump-1", Action.READ, "3-41")
        await expect(view.get_by_test_id("dv-values")).not_to_contain_text("3-41")
        await page.go_back()
        await expect(page.get_by_test_id("drives")).to_be_visible()
        assert problems == []


async def test_the_running_demo_shows_names_and_units_not_parameter_numbers(
    browser: Browser, tmp_path: Path
) -> None:
    """The real demo (simulated lines, real codecs); FCMASTER_SCREENSHOT=docs/dashboard.png
    also writes the README's screenshots from it (the fleet, and a drive's view)."""
    target = os.environ.get("FCMASTER_SCREENSHOT")
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    service = Service(with_http_listen(DEMO, f"127.0.0.1:{port}"), demo=True)
    task = asyncio.create_task(service.run(install_signals=False), name="test.demo")
    try:
        await wait_until_listening(url, timeout_s=30)
        page, problems = await _open(browser, url + "/", 1280, 900)
        await expect(page.locator("#drives tbody tr")).to_have_count(10)
        pump = page.locator('tr[data-drive="supply-pump-1"]')
        await expect(pump.get_by_test_id("values")).to_contain_text("Motor Current", timeout=15000)
        await expect(pump.get_by_test_id("values")).to_contain_text("DC Link Voltage")
        names = await page.locator("#drives .values .vname").all_text_contents()
        assert names
        assert [n for n in names if re.fullmatch(r"\d{1,2}-\d{2}", n)] == []  # never a number
        texts = await page.locator("#drives .values").all_text_contents()
        assert not [t for t in texts if re.search(r"\d{7,}", t)]  # no alarm word as a number
        if target:
            await asyncio.sleep(20)  # some history for the charts
            await page.screenshot(path=target, full_page=True)
            await page.locator('tr[data-drive="cooling-fan-1"]').get_by_test_id("open").click()
            await expect(page.locator(".u-title").first).to_be_visible()
            drive_shot = Path(target).with_name(Path(target).stem + "-drive.png")
            await page.screenshot(path=drive_shot, full_page=True)
        assert problems == []
    finally:
        service.stop()
        async with asyncio.timeout(10):
            await task


JOURNALED = """
buses:
  - name: line1
    port: sim://line1
    baudrate: 38400
    drives:
      - {{name: pump-1, address: 1}}
    simulation:
      drives:
        1: {warning}
http:
  listen: 127.0.0.1:{port}
  anonymous: viewer
journal: {{path: {journal}}}
"""


async def test_a_page_opened_after_a_restart_shows_what_happened_before(
    browser: Browser, tmp_path: Path
) -> None:
    port = free_port()
    path = tmp_path / "plant.yaml"
    journal = tmp_path / "journal.db"
    # First run: a warning comes and is kept; second run: the drive has none.
    for warning in ("{warning: {number: 59, every_s: 600, for_s: 300}}", "{}"):
        path.write_text(JOURNALED.format(port=port, journal=journal, warning=warning))
        service = Service(load_config(path))
        task = asyncio.create_task(service.run(install_signals=False), name="test.journaled")
        try:
            if warning != "{}":
                async with asyncio.timeout(30):
                    while not await service.events(kind="warning"):  # noqa: ASYNC110
                        await asyncio.sleep(0.05)  # (written by a thread: no event to wait on)
                continue
            await wait_until_listening(f"http://127.0.0.1:{port}", timeout_s=30)
            page, problems = await _open(browser, f"http://127.0.0.1:{port}/")
            events = page.get_by_test_id("events")
            await expect(events).to_contain_text("pump-1: warning 59")
            await expect(events).to_contain_text("raised")
            await page.locator('tr[data-drive="pump-1"]').get_by_test_id("open").click()
            await expect(page.get_by_test_id("dv-events")).to_contain_text("warning 59")
            assert problems == []
        finally:
            service.stop()
            async with asyncio.timeout(10):
                await task
