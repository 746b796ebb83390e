"""Simulated CiA 402 joint drive: a real CANopen node on a python-can bus around a joint
plant whose friction follows Hamon, Gautier & Garrec (eq. 21-30), plus undeclared effects.

Exception tree: every error raised on purpose derives from :class:`SimError`.
"""


class SimError(Exception):
    """Root of every error raised on purpose by :mod:`sim_drivers`."""


class PlantConfigError(SimError, ValueError):
    """A plant file is invalid; the message names the file and key."""
