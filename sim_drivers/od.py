"""Object dictionaries for the simulated CiA 402 drive: the generic EDS and vendor files.

:func:`load_drive_od` imports an EDS/DCF with canopen and makes it servable by a
``LocalNode`` acting as a drive:

- numeric variables without a default (and without a DCF ``ParameterValue``) get one, so an
  SDO upload never aborts with 0x060A0023 (maxon leaves 116 such variables, Elmo 143, among
  them 1601.0 / 1A01.0 and the unused mapping slots, see ``/work/shared/eds/PROVENANCE.md``);
  0x1000 gets the CiA 402 servo device type 0x00020192, everything else 0 (or the LowLimit
  when 0 is out of range);
- 0x6502 "supported drive modes" comes from the file when it has a default, otherwise from
  :data:`VENDOR_SUPPORTED_MODES` (keyed by the 0x1018.1 vendor number of ``[DeviceInfo]``),
  otherwise from what the file can carry (CSP when 0x607A exists, CST when 0x6071 exists).

The drive serves the live objects (0x6041, 0x6064, ...) through read callbacks; the defaults
filled here only matter for objects it does not compute.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import canopen
from canopen.objectdictionary import ObjectDictionary, ODArray, ODRecord, ODVariable
from canopen.objectdictionary import datatypes as dt

from daq.protocol.cia402 import Mode, supported_modes, supported_modes_mask
from sim_drivers import SimError


class DriveConfigError(SimError, ValueError):
    """An EDS/DCF cannot serve as a simulated CiA 402 drive; the message names file and object."""


GENERIC_EDS_NAME = "jointid_cia402.eds"

# 0x6502 for files that leave it without a default, by vendor number (0x1018.1).
VENDOR_SUPPORTED_MODES: dict[int, frozenset[Mode]] = {
    # maxon EPOS4 firmware documentation (not the EDS): PP, PV, HM, CSP, CSV, CST.
    0x000000FB: frozenset(
        {
            Mode.PROFILE_POSITION,
            Mode.PROFILE_VELOCITY,
            Mode.HOMING,
            Mode.CYCLIC_SYNC_POSITION,
            Mode.CYCLIC_SYNC_VELOCITY,
            Mode.CYCLIC_SYNC_TORQUE,
        }
    ),
    # Elmo Gold: 0x6060 HighLimit = 10 in the file; Elmo's CiA 402 reference lists PP, PV,
    # PT, HM, IP, CSP, CSV, CST for the Gold line.
    0x0000009A: frozenset(
        {
            Mode.PROFILE_POSITION,
            Mode.PROFILE_VELOCITY,
            Mode.PROFILE_TORQUE,
            Mode.HOMING,
            Mode.INTERPOLATED_POSITION,
            Mode.CYCLIC_SYNC_POSITION,
            Mode.CYCLIC_SYNC_VELOCITY,
            Mode.CYCLIC_SYNC_TORQUE,
        }
    ),
}

DEVICE_TYPE_CIA402_SERVO = 0x00020192

# struct format character per CANopen data type (little-endian packing, no padding).
STRUCT_CODE: dict[int, str] = {
    dt.BOOLEAN: "?",
    dt.INTEGER8: "b",
    dt.UNSIGNED8: "B",
    dt.INTEGER16: "h",
    dt.UNSIGNED16: "H",
    dt.INTEGER32: "i",
    dt.UNSIGNED32: "I",
    dt.INTEGER64: "q",
    dt.UNSIGNED64: "Q",
    dt.REAL32: "f",
    dt.REAL64: "d",
}


@dataclass(frozen=True)
class DriveOD:
    """An object dictionary ready to be served by :class:`sim_drivers.drive.SimulatedDrive`.

    Attributes
    ----------
    od : canopen.ObjectDictionary
        The imported dictionary, defaults filled.
    path : Path
        The EDS/DCF it came from.
    supported : frozenset[Mode]
        Modes advertised by 0x6502 (the drive refuses any other 0x6060 value).
    supported_mask : int
        The 0x6502 value served.
    filled : tuple[tuple[int, int], ...]
        ``(index, subindex)`` of the variables that had no default and were filled.
    mask_source : str
        ``"eds"``, ``"vendor table"`` or ``"objects"``: where 0x6502 came from.
    """

    od: ObjectDictionary
    path: Path
    supported: frozenset[Mode]
    supported_mask: int
    filled: tuple[tuple[int, int], ...]
    mask_source: str


def generic_eds_path() -> Path:
    """Path of the generic EDS shipped with the package (``sim_drivers/data``)."""
    return Path(str(resources.files("sim_drivers.data").joinpath(GENERIC_EDS_NAME)))


def iter_variables(od: ObjectDictionary):
    """Yield every :class:`ODVariable` of ``od`` (records' and arrays' declared sub-indices)."""
    for obj in od.values():
        if isinstance(obj, ODVariable):
            yield obj
        elif isinstance(obj, (ODRecord, ODArray)):
            yield from obj.values()


def _fill_value(var: ODVariable) -> int | float | bool:
    if var.index == 0x1000:
        return DEVICE_TYPE_CIA402_SERVO
    if var.data_type in (dt.REAL32, dt.REAL64):
        return 0.0
    if var.data_type == dt.BOOLEAN:
        return False
    lo, hi = var.min, var.max
    if lo is not None and lo > 0:
        return lo
    if hi is not None and hi < 0:
        return hi
    return 0


def load_drive_od(eds: str | Path | None = None, node_id: int = 1) -> DriveOD:
    """Import an EDS/DCF and prepare it to be served by the simulated drive.

    Parameters
    ----------
    eds : str or Path or None
        EDS/DCF path; ``None`` for the generic :data:`GENERIC_EDS_NAME`.
    node_id : int
        Node ID 1-127 (``$NODEID`` in the file resolves to it).

    Returns
    -------
    DriveOD

    Raises
    ------
    DriveConfigError
        When the file is missing, does not parse, or lacks an object the drive needs
        (0x6040, 0x6041, 0x6060, 0x6061, 0x6064).
    """
    path = generic_eds_path() if eds is None else Path(eds)
    if not 1 <= node_id <= 127:
        raise DriveConfigError(f"{path}: node id {node_id} is outside 1..127")
    if not path.is_file():
        raise DriveConfigError(f"{path}: EDS/DCF file not found")
    try:
        od = canopen.objectdictionary.import_od(str(path), node_id)
    except Exception as exc:  # canopen raises assorted errors on bad files
        raise DriveConfigError(f"{path}: not a readable EDS/DCF ({exc})") from exc
    for idx in (0x6040, 0x6041, 0x6060, 0x6061, 0x6064):
        if idx not in od:
            raise DriveConfigError(f"{path}: object 0x{idx:04X} missing; a CiA 402 drive needs it")

    filled: list[tuple[int, int]] = []
    for var in iter_variables(od):
        if var.default is None and var.value is None and var.data_type in STRUCT_CODE:
            if var.index == 0x6502:
                continue
            var.default = _fill_value(var)
            filled.append((var.index, var.subindex))

    if 0x6502 not in od:
        raise DriveConfigError(f"{path}: object 0x6502 (supported drive modes) missing")
    v6502 = od[0x6502]
    mask = v6502.value if v6502.value is not None else v6502.default
    if mask is not None:
        source = "eds"
    else:
        vendor = od.device_information.vendor_number
        if vendor in VENDOR_SUPPORTED_MODES:
            mask = supported_modes_mask(VENDOR_SUPPORTED_MODES[vendor])
            source = "vendor table"
        else:
            modes = set()
            if 0x607A in od:
                modes.add(Mode.CYCLIC_SYNC_POSITION)
            if 0x6071 in od:
                modes.add(Mode.CYCLIC_SYNC_TORQUE)
            mask = supported_modes_mask(modes)
            source = "objects"
        v6502.default = mask
        filled.append((0x6502, 0))
    return DriveOD(
        od=od,
        path=path,
        supported=supported_modes(int(mask)),
        supported_mask=int(mask),
        filled=tuple(filled),
        mask_source=source,
    )


def struct_code(var: ODVariable) -> str:
    """struct format character of a mappable numeric variable.

    Raises
    ------
    DriveConfigError
        When the data type has no fixed-size struct code (strings, domains, 24-bit ints).
    """
    try:
        return STRUCT_CODE[var.data_type]
    except KeyError:
        raise DriveConfigError(
            f"object 0x{var.index:04X}.{var.subindex} has data type 0x{var.data_type:04X}, "
            "which the simulated drive cannot map into a PDO"
        ) from None


def layout_struct(codes: list[str]) -> struct.Struct:
    """Little-endian struct for a PDO whose entries have the given format characters."""
    return struct.Struct("<" + "".join(codes))
