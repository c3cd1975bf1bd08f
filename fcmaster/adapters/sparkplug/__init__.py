"""Sparkplug B 3.0 edge node (DESIGN.md "Sparkplug B"): payload codec, session, store, adapter.

Each name is imported on first use (:mod:`fcmaster.lazy_face`): the codec needs no MQTT
client, and nothing here is loaded unless the config has a ``sparkplug`` section.
"""

from typing import TYPE_CHECKING

from fcmaster.lazy_face import lazy_face

if TYPE_CHECKING:
    from fcmaster.adapters.sparkplug.adapter import SparkplugAdapter
    from fcmaster.adapters.sparkplug.node import EdgeNode
    from fcmaster.adapters.sparkplug.payload import Payload, decode_payload, encode_payload

__all__ = ["EdgeNode", "Payload", "SparkplugAdapter", "decode_payload", "encode_payload"]

if not TYPE_CHECKING:
    __getattr__, __dir__ = lazy_face(
        __name__,
        __all__,
        {
            "fcmaster.adapters.sparkplug.adapter": ("SparkplugAdapter",),
            "fcmaster.adapters.sparkplug.node": ("EdgeNode",),
            "fcmaster.adapters.sparkplug.payload": ("Payload", "decode_payload", "encode_payload"),
        },
    )
