"""fcmaster: the RS-485 master for fleets of variable frequency drives."""

__version__ = "0.1.0"

__all__ = ["__version__"]
