"""Connecting as the config says: credentials from the environment, TLS with a client
certificate. The broker and the certificates are real (mosquitto, openssl)."""

from __future__ import annotations

import asyncio
import shutil
import ssl
from pathlib import Path

import pytest
from structlog.testing import capture_logs

from fcmaster.adapters.mqtt import MqttAdapter
from fcmaster.adapters.settings import MqttSettings, TlsSettings
from fcmaster.config import parse
from fcmaster.errors import ConfigError
from fcmaster.service import Service
from tests.integration.mosquitto import Broker, Recorder, payload_text
from tests.integration.mqtt_gateway import FakeGateway

LIMIT_S = 20.0
CONFIG = """
buses:
  - name: line1
    port: sim://line1
    baudrate: 115200
    drives: [{name: pump-1, address: 1}]
mqtt:
  url: URL
  client_id: gateway-7
  reconnect_min_s: 0.05
  reconnect_max_s: 0.2
"""


async def run(*argv: str | Path) -> None:
    tool = shutil.which(str(argv[0]))
    if tool is None:
        pytest.fail(f"{argv[0]} is not installed")
    process = await asyncio.create_subprocess_exec(
        tool, *map(str, argv[1:]),
        stdout=asyncio.subprocess.DEVNULL, stderr=asyncio.subprocess.PIPE,
    )  # fmt: skip
    _, error = await process.communicate()
    assert process.returncode == 0, error.decode()


async def test_the_password_comes_from_the_environment(tmp_path: Path) -> None:
    passwords = tmp_path / "passwords"
    await run("mosquitto_passwd", "-b", "-c", passwords, "gateway", "s3cret-from-env")
    await run("mosquitto_passwd", "-b", passwords, "viewer", "viewer-pw")
    broker = Broker(tmp_path, extra=f"allow_anonymous false\npassword_file {passwords}")
    text = CONFIG.replace("URL", broker.url) + (
        "  username: gateway\n  password: ${FCM_MQTT_PASSWORD}\n"
    )
    async with asyncio.timeout(LIMIT_S), broker:
        good = Service(parse(text, env={"FCM_MQTT_PASSWORD": "s3cret-from-env"}))
        running = asyncio.create_task(good.run(install_signals=False))
        async with Recorder(broker, "fcmaster/#", username="viewer", password="viewer-pw") as c:
            await c.wait("fcmaster/status", lambda m: payload_text(m) == "online")
            good.stop()
            await running
            await c.wait("fcmaster/status", lambda m: payload_text(m) == "offline")

        bad = Service(parse(text, env={"FCM_MQTT_PASSWORD": "wrong"}))
        with capture_logs() as logs:
            running = asyncio.create_task(bad.run(install_signals=False))
            await asyncio.sleep(0.5)
            bad.stop()
            await running
    failures = [e for e in logs if e["event"] == "mqtt.connect_failed"]
    assert len(failures) >= 2  # it keeps trying, with backoff
    assert "authori" in failures[0]["error"].lower()
    assert not any(e["event"] == "mqtt.connected" for e in logs)


async def certificates(directory: Path) -> None:
    """A CA, a server certificate for 127.0.0.1 and a client certificate, signed by the CA."""
    await run("openssl", "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "1",
              "-subj", "/CN=fcmaster test CA", "-keyout", directory / "ca.key",
              "-out", directory / "ca.crt")  # fmt: skip
    for name, san in (("server", "IP:127.0.0.1,DNS:localhost"), ("client", "DNS:gateway-7")):
        (directory / f"{name}.ext").write_text(f"subjectAltName={san}\n")
        key, csr, crt = (directory / f"{name}.{suffix}" for suffix in ("key", "csr", "crt"))
        await run("openssl", "req", "-newkey", "rsa:2048", "-nodes", "-subj", f"/CN={name}",
                  "-keyout", key, "-out", csr)  # fmt: skip
        await run("openssl", "x509", "-req", "-in", csr, "-days", "1", "-CA", directory / "ca.crt",
                  "-CAkey", directory / "ca.key", "-CAcreateserial",
                  "-extfile", directory / f"{name}.ext", "-out", crt)  # fmt: skip


async def test_tls_with_a_ca_and_a_client_certificate(tmp_path: Path) -> None:
    await certificates(tmp_path)
    broker = Broker(tmp_path, extra="\n".join([
        f"cafile {tmp_path / 'ca.crt'}", f"certfile {tmp_path / 'server.crt'}",
        f"keyfile {tmp_path / 'server.key'}", "require_certificate true",
    ]))  # fmt: skip
    text = CONFIG.replace("URL", f"mqtts://127.0.0.1:{broker.port}") + (
        f"  tls: {{ca: {tmp_path / 'ca.crt'}, cert: {tmp_path / 'client.crt'}, "
        f"key: {tmp_path / 'client.key'}}}\n"
    )
    observer_tls = ssl.create_default_context(cafile=tmp_path / "ca.crt")
    observer_tls.load_cert_chain(tmp_path / "client.crt", tmp_path / "client.key")
    async with asyncio.timeout(LIMIT_S), broker:
        service = Service(parse(text))
        running = asyncio.create_task(service.run(install_signals=False))
        async with Recorder(broker, "fcmaster/#", tls_context=observer_tls) as client:
            await client.wait("fcmaster/status", lambda m: payload_text(m) == "online")
            await client.wait_json("fcmaster/line1/pump-1/state")
            service.stop()
            await running


def test_unreadable_certificates_are_a_config_error(tmp_path: Path) -> None:
    missing = tmp_path / "none"
    with pytest.raises(ConfigError) as caught:  # `check` says so, as `run` would
        parse(CONFIG.replace("URL", "mqtts://127.0.0.1:8883") + f"  tls: {{ca: {missing}}}\n")
    assert caught.value.problems == [("mqtt.tls.ca", f"cannot read {missing}")]
    model = MqttSettings(url="mqtts://127.0.0.1:8883", tls=TlsSettings(ca=str(missing)))
    with pytest.raises(ConfigError, match=r"mqtt\.tls"):
        MqttAdapter(model, FakeGateway())


@pytest.mark.parametrize(
    ("section", "path", "reason"),
    [
        ("{url: 'http://broker'}", "mqtt.url", "mqtt://host:port"),
        ("{url: 'mqtt://user:pw@broker'}", "mqtt.url", "mqtt.username"),
        ("{url: 'mqtt://broker:99999'}", "mqtt.url", "port"),
        ("{tls: {ca: ca.crt}}", "mqtt", "mqtts://"),
        ("{url: 'mqtts://broker', tls: {key: k.pem}}", "mqtt", "tls.cert"),
        ("{base_topic: 'plant/#'}", "mqtt.base_topic", "wildcards"),
        ("{status_topic: '/gw/status'}", "mqtt.status_topic", "leading"),
        ("{reconnect_min_s: 5, reconnect_max_s: 1}", "mqtt", "reconnect_min_s"),
    ],
    ids=["scheme", "credentials-in-url", "port", "tls-on-plain", "key-without-cert",
         "wildcard-base", "slash-status", "backoff"],
)  # fmt: skip
def test_mqtt_settings_are_checked_with_their_key_path(
    section: str, path: str, reason: str
) -> None:
    with pytest.raises(ConfigError) as caught:
        parse(f"buses: [{{name: line1, port: sim://line1}}]\nmqtt: {section}\n")
    [(where, why)] = caught.value.problems
    assert where == path
    assert reason.lower() in why.lower()


def test_names_that_cannot_be_topic_levels_are_config_errors() -> None:
    text = "buses: [{name: 'a/b', port: sim://x, drives: [{name: 'p+1', address: 1}]}]\n"
    for tail in ("", "mqtt: {}\n"):  # with MQTT or without: every surface must address them
        with pytest.raises(ConfigError) as caught:
            parse(text + tail)
        assert [where for where, _ in caught.value.problems] == [
            "buses[0].name",
            "buses[0].drives[0].name",
        ]
