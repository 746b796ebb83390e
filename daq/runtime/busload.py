"""CAN bus load of a cyclic configuration, with worst-case bit stuffing.

A classic CAN 2.0A data frame (11-bit identifier) with ``n`` data bytes has
``47 + 8 n`` bits on the wire without stuffing (SOF, identifier, RTR, IDE, r0, DLC, data,
CRC, CRC delimiter, ACK slot and delimiter, EOF, 3-bit intermission). Stuffing applies to the
``34 + 8 n`` bits from SOF to the end of the CRC; in the worst case one stuff bit is added
every four bits after the first, hence::

    bits(n) = 47 + 8 n + floor((34 + 8 n - 1) / 4)

An empty frame (SYNC) is 55 bits; an 8-byte frame is 111 bits unstuffed and 135 bits with
worst-case stuffing (the range quoted in ``notes/performance.md``).

Budget: every bus (``[[daq.drives]] channel``) carries one SYNC per cycle plus the PDOs of its
own drives; a configuration whose cyclic traffic exceeds ``daq.max_bus_load`` of the bit rate
on any bus is refused before anything moves (:func:`check_loads`), in one line with the
figures and the two ways out: the highest cycle rate that fits (:func:`max_rate_hz`) and the
number of buses the drives need at the planned rate (:func:`drives_per_bus`).

Pure: no bus access.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

from daq import ConfigError


def frame_bits(n_bytes: int) -> int:
    """Worst-case length on the wire of a standard (11-bit id) data frame [bit].

    Parameters
    ----------
    n_bytes : int
        Data length code, 0..8.

    Returns
    -------
    int
        ``47 + 8 n + floor((34 + 8 n - 1) / 4)`` bits (stuffing over SOF..CRC).
    """
    if not 0 <= n_bytes <= 8:
        raise ValueError(f"CAN data length must be 0..8 bytes, got {n_bytes}")
    return 47 + 8 * n_bytes + (34 + 8 * n_bytes - 1) // 4


@dataclass(frozen=True)
class BusLoad:
    """Bus load of one control cycle.

    Attributes
    ----------
    frames_per_cycle : int
        SYNC + every RPDO + every TPDO of every drive.
    bits_per_cycle : int
        Worst-case stuffed bits per cycle [bit].
    cycle_s : float
        Cycle time [s].
    bitrate : int
        Bus bit rate [bit/s].
    drive_bits : tuple of int
        Worst-case bits per cycle of each drive's PDOs (without the SYNC) [bit].
    sync_bits : int
        Bits of the SYNC frame per cycle (0 without SYNC) [bit].
    channel : str
        The bus (``daq.channel`` or a drive's ``channel``), for messages.
    """

    frames_per_cycle: int
    bits_per_cycle: int
    cycle_s: float
    bitrate: int
    drive_bits: tuple[int, ...] = ()
    sync_bits: int = 0
    channel: str = ""

    @property
    def share(self) -> float:
        """Share of the bit rate used by the cyclic traffic (0..1, can exceed 1)."""
        return self.bits_per_cycle / (self.cycle_s * self.bitrate)

    def __str__(self) -> str:
        return (
            f"{self.frames_per_cycle} frames/cycle, {self.bits_per_cycle} bit/cycle, "
            f"{100 * self.share:.1f} % of {self.bitrate / 1000:g} kbit/s at "
            f"{1000 * self.cycle_s:g} ms"
        )


def cycle_load(
    pdo_lengths: Iterable[Sequence[int]], cycle_s: float, bitrate: int, *, sync: bool = True,
    channel: str = "",
) -> BusLoad:
    """Bus load of the cyclic traffic.

    Parameters
    ----------
    pdo_lengths : iterable of sequences of int
        Per drive, the data lengths [byte] of every RPDO and TPDO exchanged each cycle.
    cycle_s : float
        Cycle time [s].
    bitrate : int
        Bit rate [bit/s].
    sync : bool
        Count one SYNC frame (0 bytes) per cycle.
    channel : str
        Name of the bus, for messages.
    """
    frames = 1 if sync else 0
    sync_bits = frame_bits(0) if sync else 0
    drive_bits = []
    for lengths in pdo_lengths:
        drive_bits.append(sum(frame_bits(n) for n in lengths))
        frames += len(lengths)
    return BusLoad(frames, sync_bits + sum(drive_bits), float(cycle_s), int(bitrate),
                   tuple(drive_bits), sync_bits, channel)


def max_rate_hz(load: BusLoad, max_share: float) -> float:
    """Highest cycle rate [Hz] at which ``load``'s traffic stays within ``max_share``:
    ``max_share * bitrate / bits_per_cycle``."""
    return max_share * load.bitrate / load.bits_per_cycle if load.bits_per_cycle else math.inf


def drives_per_bus(load: BusLoad, max_share: float) -> int:
    """How many drives like the heaviest of ``load`` fit on one bus at ``load.cycle_s``
    within ``max_share`` (each bus has its own SYNC); 0 when not even one fits."""
    if not load.drive_bits:
        return 0
    budget = max_share * load.cycle_s * load.bitrate - load.sync_bits
    return max(0, int(budget // max(load.drive_bits)))


def refusal(load: BusLoad, max_share: float, source: str = "campaign") -> str:
    """The one-line refusal of a bus over budget: the figures, then the highest rate that
    fits and, when one drive fits, how many buses the drives need at the planned rate."""
    n = len(load.drive_bits)
    where = ", ".join(x for x in (f"bus {load.channel!r}" if load.channel else "",
                                  f"{n} drive{'s' if n != 1 else ''}" if n else "") if x)
    rate = max_rate_hz(load, max_share)
    # rate rounded down (and cycle rounded up) to 3 significant figures, so that it fits
    digits = 2 - int(math.floor(math.log10(rate))) if rate > 0 else 0
    rate_shown = math.floor(rate * 10**digits) / 10**digits
    cycle_us = math.ceil(1e6 / rate) if rate > 0 else 0
    ways = f"lower the rate to <= {rate_shown:g} Hz (control.cycle_s >= {cycle_us / 1e6:g} s)"
    per_bus = drives_per_bus(load, max_share)
    if n > 1 and per_bus >= 1:
        buses = -(-n // per_bus)
        ways += (f" or spread the drives over {buses} buses ({per_bus} drive"
                 f"{'s' if per_bus > 1 else ''} per bus fit at {1 / load.cycle_s:g} Hz)")
    elif n == 1:
        ways += " (one drive alone is over budget at this rate)"
    where = f" ({where})" if where else ""
    return (f"{source}: daq.max_bus_load: cyclic traffic needs {load}{where} "
            f"> allowed {100 * max_share:g} %; {ways}")


def check_load(load: BusLoad, max_share: float, source: str = "campaign") -> None:
    """Refuse a configuration whose cyclic traffic exceeds ``max_share`` of the bit rate.

    Raises
    ------
    daq.ConfigError
        One line (:func:`refusal`): ``"<source>: daq.max_bus_load: cyclic traffic needs 10
        frames/cycle, 1060 bit/cycle, 106.0 % of 1000 kbit/s at 1 ms (bus 'can0', 3 drives)
        > allowed 60 %; lower the rate to <= 566 Hz (control.cycle_s >= 0.001767 s) or spread
        the drives over 3 buses (1 drive per bus fit at 1000 Hz)"``.
    """
    if load.share > max_share:
        raise ConfigError(refusal(load, max_share, source))


def bus_loads(pdo_lengths: Mapping[str, Iterable[Sequence[int]]], cycle_s: float,
              bitrate: int) -> dict[str, BusLoad]:
    """:func:`cycle_load` of every bus: channel -> per drive PDO lengths [byte]."""
    return {ch: cycle_load(lengths, cycle_s, bitrate, channel=ch)
            for ch, lengths in pdo_lengths.items()}


def check_loads(loads: Mapping[str, BusLoad], max_share: float,
                source: str = "campaign") -> BusLoad:
    """:func:`check_load` on every bus (the most loaded first); returns the most loaded.

    Raises
    ------
    daq.ConfigError
        The refusal of the most loaded bus over budget.
    """
    if not loads:
        raise ValueError("check_loads: no bus")
    worst = max(loads.values(), key=lambda ld: ld.share)
    check_load(worst, max_share, source)
    return worst
