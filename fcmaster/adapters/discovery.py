"""Home Assistant MQTT discovery: each drive a device, its state as entities.

Config messages go, retained, to ``{prefix}/{component}/{node}/{object}/config``, where
``node`` is ``{base}_{bus}_{drive}`` made safe for a topic level. Every drive gets sensors
(output frequency, commanded reference, and one per measured value as it first appears —
current, power, voltage, … with the device class its unit implies) and binary sensors
(running, fault, warning). Only ``control: bus`` drives get buttons (start, stop) and a
number entity for the reference in Hz, bounded by the drive's configured limits — and only
when MQTT commands are on without tokens (``mqtt.trust_broker``): Home Assistant's buttons
cannot carry a token, which would be retained in their configs for all to read. Entities
are available while both the gateway (its status topic) and the drive are online.
"""

from __future__ import annotations

import json
import re
from typing import Any

import fcmaster
from fcmaster.adapters.mqtt_topics import Topics
from fcmaster.bus.plan import DrivePlan
from fcmaster.protocol.registry import PROTOCOLS
from fcmaster.state import DriveState

HA_COMMAND_ID = "homeassistant"  # the id commands from Home Assistant's entities carry

_UNITS: dict[str, tuple[str | None, str, str]] = {  # unit → device class, state class, label
    "Hz": ("frequency", "measurement", "Frequency"),
    "A": ("current", "measurement", "Current"),
    "V": ("voltage", "measurement", "Voltage"),
    "kW": ("power", "measurement", "Power"),
    "kWh": ("energy", "total_increasing", "Energy"),
    "°C": ("temperature", "measurement", "Temperature"),
    "h": ("duration", "total_increasing", "Running hours"),
    "Nm": (None, "measurement", "Torque"),
    "rpm": (None, "measurement", "Speed"),
    "%": (None, "measurement", "Value"),
}
_UNSAFE = re.compile(r"[^A-Za-z0-9_-]")


class Discovery:
    """Builds the config messages for one base topic and discovery prefix."""

    def __init__(self, topics: Topics, prefix: str, *, controls: bool = True) -> None:
        """Configs under ``prefix`` for the drives under ``topics`` (``controls``: buttons)."""
        self._topics = topics
        self._prefix = prefix
        self._controls = controls

    def node(self, state: DriveState) -> str:
        """The drive's node id: ``{base}_{bus}_{drive}``, safe as a topic level."""
        return _UNSAFE.sub("_", f"{self._topics.base}_{state.bus}_{state.name}")

    def drive(self, state: DriveState, plan: DrivePlan | None) -> list[tuple[str, bytes]]:
        """``(topic, payload)`` for every entity a drive has from the start."""
        configs = [
            self._sensor(
                state,
                "output_frequency",
                "Output frequency",
                "{{ value_json.output_frequency_hz }}",
                "Hz",
                "frequency",
            ),
            self._sensor(
                state, "reference", "Reference", "{{ value_json.reference_pct }}", "%", None
            ),
            self._binary(state, "running", "Running", "running", "running"),
            self._binary(state, "fault", "Fault", "fault", "problem"),
            self._binary(state, "warning", "Warning", "warning", "problem"),
        ]
        if plan is not None and plan.control and self._controls:
            configs += [
                self._button(state, "start", "Start"),
                self._button(state, "stop", "Stop"),
                self._reference(state, plan),
            ]
        return configs

    def value(self, state: DriveState, name: str, unit: str) -> tuple[str, bytes]:
        """``(topic, payload)`` of the sensor for the measured value ``name``."""
        device_class, state_class, label = _UNITS.get(unit, (None, "measurement", "Value"))
        key = json.dumps(name)
        template = (
            f"{{{{ value_json['values'][{key}]['value'] "
            f"if {key} in value_json['values'] else None }}}}"
        )
        return self._sensor(
            state,
            f"value_{name}",
            f"{label} {name}",
            template,
            unit or None,
            device_class,
            state_class=state_class,
        )

    # -- entities ---------------------------------------------------------------------------

    def _config(
        self, component: str, state: DriveState, object_id: str, name: str, **fields: Any
    ) -> tuple[str, bytes]:
        node = self.node(state)
        object_id = _UNSAFE.sub("_", object_id)
        payload = {
            "name": name,
            "unique_id": f"{node}_{object_id}",
            "availability": [
                {"topic": self._topics.status},
                {"topic": self._topics.availability(state.bus, state.name)},
            ],
            "availability_mode": "all",
            "qos": 1,
            "device": {
                "identifiers": [node],
                "name": state.name,
                "manufacturer": _manufacturer(state.protocol),
                "model": f"{state.protocol} drive, address {state.address} on {state.bus}",
            },
            "origin": {"name": "fcmaster", "sw_version": fcmaster.__version__},
            **fields,
        }
        topic = f"{self._prefix}/{component}/{node}/{object_id}/config"
        return topic, json.dumps(payload, ensure_ascii=False).encode()

    def _sensor(
        self,
        state: DriveState,
        object_id: str,
        name: str,
        template: str,
        unit: str | None,
        device_class: str | None,
        *,
        state_class: str = "measurement",
    ) -> tuple[str, bytes]:
        fields: dict[str, Any] = {
            "state_topic": self._topics.state(state.bus, state.name),
            "value_template": template,
            "state_class": state_class,
        }
        if unit:
            fields["unit_of_measurement"] = unit
        if device_class:
            fields["device_class"] = device_class
        return self._config("sensor", state, object_id, name, **fields)

    def _binary(
        self, state: DriveState, object_id: str, name: str, field: str, device_class: str
    ) -> tuple[str, bytes]:
        return self._config(
            "binary_sensor",
            state,
            object_id,
            name,
            state_topic=self._topics.state(state.bus, state.name),
            value_template=f"{{{{ 'ON' if value_json.{field} else 'OFF' }}}}",
            payload_on="ON",
            payload_off="OFF",
            device_class=device_class,
        )

    def _button(self, state: DriveState, action: str, name: str) -> tuple[str, bytes]:
        return self._config(
            "button",
            state,
            action,
            name,
            command_topic=self._topics.command(state.bus, state.name),
            payload_press=json.dumps({"id": HA_COMMAND_ID, "action": action}),
        )

    def _reference(self, state: DriveState, plan: DrivePlan) -> tuple[str, bytes]:
        hz = f"(value_json.reference_pct or 0) * {plan.nominal_frequency_hz} / 100"
        return self._config(
            "number",
            state,
            "reference_hz",
            "Reference",
            command_topic=self._topics.command(state.bus, state.name),
            command_template=(
                f'{{"id": "{HA_COMMAND_ID}", "action": "set_reference", '
                '"frequency_hz": {{ value }}}'
            ),
            state_topic=self._topics.state(state.bus, state.name),
            value_template=f"{{{{ ({hz}) | round(2) }}}}",
            min=plan.min_frequency_hz,
            max=plan.max_frequency_hz,
            step=0.1,
            unit_of_measurement="Hz",
            device_class="frequency",
            mode="box",
        )


def _manufacturer(protocol: str) -> str:
    spec = PROTOCOLS.get(protocol)
    return spec.manufacturer if spec else protocol
