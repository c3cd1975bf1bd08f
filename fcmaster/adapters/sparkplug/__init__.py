"""Sparkplug B 3.0 edge node (DESIGN.md "Sparkplug B"): payload codec, session, store, adapter."""
