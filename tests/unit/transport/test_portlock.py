import os
from pathlib import Path

from fcmaster.transport.portlock import in_use_message


def test_the_holder_is_named_from_the_lock_table(tmp_path: Path) -> None:
    port = tmp_path / "ttyX"
    port.write_bytes(b"")
    node = os.stat(port)
    where = f"{os.major(node.st_dev):02x}:{os.minor(node.st_dev):02x}:{node.st_ino}"
    holder = os.getppid()
    locks = tmp_path / "locks"
    locks.write_text(
        f"1: POSIX  ADVISORY  WRITE 7 {where} 0 EOF\n"  # not an flock
        f"2: FLOCK  ADVISORY  WRITE {holder} {where} 0 EOF\n"
        f"2: -> FLOCK  ADVISORY  WRITE 99 {where} 0 EOF\n"  # a waiter, not the holder
        f"3: FLOCK  ADVISORY  WRITE {os.getpid()} {where} 0 EOF\n"  # ourselves
        "4: FLOCK  ADVISORY  WRITE 5 00:00:1 0 EOF\n"
    )
    message = in_use_message(str(port), locks=locks)
    assert message.startswith(f"port {port} is in use by PID {holder} (")
    assert message.count("PID") == 1


def test_without_a_lock_table_the_port_is_in_use_by_another_program(tmp_path: Path) -> None:
    message = in_use_message("/dev/ttyNONE", locks=tmp_path / "absent")
    assert message == "port /dev/ttyNONE is in use by another program"
