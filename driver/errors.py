"""Exception hierarchy and the CLI exit code each maps to.

Every error the driver raises on bad input derives from :class:`GyrostarError`, so a
caller (the loop, the CLI) can catch one type and never crash on a device's mistakes.
"""


class GyrostarError(Exception):
    """Base of every gyrostar error. ``exit_code`` is what the CLI exits with."""

    exit_code = 1


class ConfigError(GyrostarError, ValueError):
    """A configuration file or value is malformed (unknown key, wrong type, bad range)."""

    exit_code = 2


class DeviceError(GyrostarError, IOError):
    """A device or link misbehaved: NACK, timeout, corrupt frame, firmware rejection."""

    exit_code = 3


class LinkLostError(DeviceError):
    """The link itself is gone (port closed, device unplugged, write failed): reconnect."""


class NotAvailableError(GyrostarError, RuntimeError):
    """A feature needs something this machine lacks (optional package, tool, device)."""

    exit_code = 4


EXIT_CODES = {
    0: "success",
    1: "the command ran but a check or acceptance criterion failed",
    2: "usage or configuration error (bad argument, unknown or ill-typed config key)",
    3: "device or link error (no reply, NACK, corrupt frames, firmware rejection)",
    4: "not available here (missing optional package, tool or device)",
    130: "interrupted (Ctrl-C)",
}
