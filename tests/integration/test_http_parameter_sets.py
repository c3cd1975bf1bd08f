"""Parameter sets over the daemon's HTTP API: a real Service, simulated lines, real sockets."""

from __future__ import annotations

import time

import httpx
from structlog.testing import capture_logs

from fcmaster.adapters.readlimit import VIEWER_READ_GAP_S
from tests.integration.http_harness import OPERATOR, VIEWER, service_config
from tests.integration.ports import free_port
from tests.integration.test_http_service import running


async def test_a_drives_set_is_read_through_the_bus_and_drift_is_reported() -> None:
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    with capture_logs() as logs:
        async with (
            running(service_config(port), url),
            httpx.AsyncClient(base_url=url, timeout=30) as client,
        ):
            # A viewer's set: each read takes its turn of the line's viewer-read spacing.
            started = time.monotonic()
            response = await client.get("/api/v1/drives/pump-1/parameters", headers=VIEWER)
            took = time.monotonic() - started
            assert response.status_code == 200, response.text
            assert took >= (5 + 19 - 1) * VIEWER_READ_GAP_S
            saved = response.json()
            assert (saved["protocol"], saved["address"]) == ("danfoss-fc", 1)
            assert saved["identity"]["15-40"]["value"] == "FC-302"
            assert saved["parameters"]["3-41"] == {
                "name": "Ramp 1 Ramp Up Time", "value": 3.0, "unit": "s", "raw": 300,
            }  # fmt: skip
            assert saved["parameters"]["8-31"]["raw"] == 1  # its address, as configured
            # The operator's reads are not spaced out; everything below goes as the operator.
            fan = (await client.get("/api/v1/drives/fan-2/parameters", headers=OPERATOR)).json()
            assert fan["parameters"]["8-31"]["raw"] == 7

            equal = await client.post(
                "/api/v1/drives/pump-1/parameters/diff", json=saved, headers=OPERATOR
            )
            assert equal.status_code == 200, equal.text
            assert (equal.json()["equal"], equal.json()["differences"]) == (True, [])

            write = await client.put(
                "/api/v1/drives/pump-1/parameters/3-41", json={"value": 6.0}, headers=OPERATOR
            )
            assert write.json()["outcome"] == "done"
            drifted = await client.post(
                "/api/v1/drives/pump-1/parameters/diff", json=saved, headers=OPERATOR
            )
            report = drifted.json()
            assert report["equal"] is False
            assert [
                (d["parameter"], d["saved"]["raw"], d["drive"]["raw"])
                for d in report["differences"]
            ] == [("3-41", 300, 600)]

            fleet = await client.post(
                "/api/v1/parameters/diff", json={"pump-1": saved, "fan-2": fan}, headers=OPERATOR
            )
            assert fleet.status_code == 200, fleet.text
            by_drive = {entry["drive"]: entry for entry in fleet.json()}
            assert by_drive["pump-1"]["equal"] is False
            assert by_drive["fan-2"]["equal"] is True

            # Bad input: named, and nothing read.
            bad = await client.post(
                "/api/v1/drives/pump-1/parameters/diff",
                json={"protocol": "danfoss-fc"},
                headers=VIEWER,
            )
            assert bad.status_code == 422
            assert "format" in bad.json()["reason"]
            assert "parameters" in bad.json()["reason"]
            unknown = await client.post(
                "/api/v1/parameters/diff", json={"pump-9": saved}, headers=VIEWER
            )
            assert unknown.status_code == 422
            assert "pump-9" in unknown.json()["reason"]
            missing = await client.get("/api/v1/drives/pump-9/parameters", headers=VIEWER)
            assert missing.status_code == 404
            anonymous = await client.get("/api/v1/drives/pump-1/parameters")
            assert anonymous.status_code == 401
    # Every value came through the bus's command path as ordinary reads: the viewer's one
    # set, then the operator's five (a GET, two drive diffs, a fleet diff of two drives),
    # each 5 identity texts + 19 settings.
    reads = [e for e in logs if e["event"] == "command.completed" and e.get("actor")]
    by_actor = {a: [e for e in reads if e["actor"] == a] for a in ("scada", "ops")}
    assert {e["command"] for e in reads if e["actor"] in by_actor} == {"read", "write"}
    assert len(by_actor["scada"]) == 5 + 19
    assert len([e for e in by_actor["ops"] if e["command"] == "read"]) == 5 * (5 + 19)


MODBUS_CONFIG = """
buses:
  - name: rtu
    port: sim://rtu
    protocol: modbus-rtu
    baudrate: 115200
    drives:
      - {{name: yaskawa, address: 4, control: bus, profile: yaskawa-memobus}}
http:
  listen: 127.0.0.1:{port}
  tokens:
    - {{name: ops, role: operator, token: "{operator}"}}
"""


async def test_a_modbus_drives_set_over_http_is_its_profiles() -> None:
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    text = MODBUS_CONFIG.format(port=port, operator=OPERATOR["Authorization"].split()[-1])
    async with running(text, url), httpx.AsyncClient(base_url=url, timeout=30) as client:
        response = await client.get("/api/v1/drives/yaskawa/parameters", headers=OPERATOR)
        assert response.status_code == 200, response.text
        saved = response.json()
        assert (saved["protocol"], saved["address"]) == ("modbus-rtu", 4)
        assert list(saved["parameters"]) == ["hr512", "hr513", "hr1077", "hr1064", "hr1065"]
        assert saved["parameters"]["hr512"] == {
            "name": "C1-01 Acceleration Time 1", "value": 10.0, "unit": "s", "raw": 100,
        }  # fmt: skip
