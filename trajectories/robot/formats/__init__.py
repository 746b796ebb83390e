"""Robot file formats behind a suffix table: a new format is one module with
``read(path) -> Robot`` and one row of :data:`FORMATS` (docs/robot-format.md, "Adding a
format"), like python-can's ``MESSAGE_WRITERS``.

========  ==========================================================================
suffix    module
========  ==========================================================================
.toml     :mod:`.mdh_toml`: MDH table or ``urdf = ...``, drives, limits, motion
.urdf     :mod:`.urdf`: every joint moves, no drive data
.xml      :mod:`.mjcf`: MuJoCo MJCF through pinocchio's parser (also ``.mjcf``)
========  ==========================================================================

``"example-robot-data:<name>"`` loads a URDF packaged by example-robot-data.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from .. import RobotError
from ..description import Robot
from . import mdh_toml, mjcf, urdf

__all__ = ["FORMATS", "load_robot"]

#: File suffix (lower case) -> reader ``(path) -> Robot``.
FORMATS: dict[str, Callable[[Path], Robot]] = {
    ".toml": mdh_toml.read,
    ".urdf": urdf.read,
    ".xml": mjcf.read,
    ".mjcf": mjcf.read,
}


def load_robot(path: str | Path) -> Robot:
    """Read a robot file by its suffix (:data:`FORMATS`).

    Parameters
    ----------
    path : str or Path
        The file; ``"example-robot-data:ur10"`` loads the packaged UR10 URDF directly.

    Returns
    -------
    Robot

    Raises
    ------
    RobotError
        Unknown suffix, unreadable file, URDF that does not parse, both or neither of
        ``urdf`` and an MDH table, unknown joint, invalid drive data or limits, locked value
        missing, ... (one line naming the file and the element).
    """
    text = str(path)
    if text.startswith(urdf.LOCATOR):
        return urdf.read_example(text[len(urdf.LOCATOR):], text)
    p = Path(path)
    reader = FORMATS.get(p.suffix.lower())
    if reader is None:
        raise RobotError(f"{text}: expected a robot file ending in "
                         f"{', '.join(FORMATS)} (docs/robot-format.md), got "
                         f"{p.suffix or 'no suffix'!r}")
    return reader(p)
