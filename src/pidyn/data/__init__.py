"""Records and the readers of the measured formats. The readers are imported here so that
``Record.from_csmip`` and ``Record.from_xsens`` find them (``sources.READERS``) while the record
does not import the modules that build it."""

from pidyn.data import imu, strong_motion  # noqa: F401  (each adds its reader to sources.READERS)
