"""The OPC UA server's own process: its pipe to the daemon, address space, users and pki.

Only :mod:`.wire` and :mod:`.quality` may be imported by the daemon: the rest needs asyncua,
which a daemon without an ``opcua:`` section never loads.
"""
