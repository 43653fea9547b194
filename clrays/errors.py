"""Errors that reach the user as one line (the CLI prints them without a traceback)."""


class ClraysError(Exception):
    """Base class: anything the CLI reports as `clrays: error: <message>` with exit code 1."""


class SceneError(ClraysError):
    """A scene file (or an override) is invalid.

    The message reads like a compiler's: `scenes/x.yaml:14:9: light.cone_deg: expected (0, 90], got 120`.
    """


class DeviceError(ClraysError):
    """No usable OpenCL device, or a kernel failed to build."""


class OutputError(ClraysError):
    """The output path cannot be written or has an unknown extension."""
