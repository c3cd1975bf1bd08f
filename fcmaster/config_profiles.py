"""A drive's ``profile:`` key: a built-in drive profile's name, or a YAML file of its own.

Only protocols whose drives follow profiles (``ProtocolSpec.new_profiled_codec``: modbus-rtu)
take the key, and their drives need it: a Modbus drive's registers and control words are
its family's, and guessing them could start a motor by the wrong word. A file is read
relative to the config file's directory and judged with every problem named.
"""

from __future__ import annotations

from pathlib import Path

from fcmaster.errors import ConfigError
from fcmaster.protocol.registry import spec_for


def drive_profile(
    protocol: str,
    profile: str | None,
    base: Path,
    at: str,
    problems: list[tuple[str, str]],
    line_default: str | None = None,
) -> object:
    """The profile ``profile`` names for a drive at key path ``at``.

    None: the line's ``profile`` (``line_default``) serves the drive, or a problem is noted.
    """
    from fcmaster.protocol.modbus_rtu.profile_file import parse_profile_text
    from fcmaster.protocol.modbus_rtu.profiles import BUILT_IN

    where = f"{at}.profile"
    takes = spec_for(protocol).new_profiled_codec is not None
    if profile is None:
        if takes and line_default is None:
            problems.append(
                (
                    where,
                    f"a {protocol} drive needs a profile: one of {', '.join(BUILT_IN)}, "
                    "or the path of a profile file (or the line's profile: for all of them)",
                )
            )
        return None
    if not takes:
        problems.append((where, f"only drives on modbus-rtu lines have a profile, not {protocol}"))
        return None
    if profile in BUILT_IN:
        return BUILT_IN[profile]
    path = Path(profile).expanduser()
    if not path.is_absolute():
        path = base / path
    if not path.exists() and path.suffix not in (".yaml", ".yml"):
        problems.append(
            (where, f"{profile!r} is neither a built-in ({', '.join(BUILT_IN)}) nor a file")
        )
        return None
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        problems.append((where, f"cannot read {path}: {exc.strerror or exc}"))
        return None
    try:
        return parse_profile_text(text, f"{path}: ")
    except ConfigError as exc:
        problems.extend((where, f"{inner}: {reason}") for inner, reason in exc.problems)
        return None


def profile_monitor(profile: object) -> tuple[str, ...] | None:
    """What a drive without ``monitor:`` watches: its profile's values (None: no profile).

    Each drive its own: the codec's default monitor is every profile's on the line.
    """
    from fcmaster.protocol.modbus_rtu.keys import register_key
    from fcmaster.protocol.modbus_rtu.profile import DriveProfile

    if not isinstance(profile, DriveProfile):
        return None
    return tuple(register_key(value.register).name for value in profile.values)
