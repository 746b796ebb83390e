"""CAN bus load of a cyclic configuration, with worst-case bit stuffing.

A classic CAN 2.0A data frame (11-bit identifier) with ``n`` data bytes has
``47 + 8 n`` bits on the wire without stuffing (SOF, identifier, RTR, IDE, r0, DLC, data,
CRC, CRC delimiter, ACK slot and delimiter, EOF, 3-bit intermission). Stuffing applies to the
``34 + 8 n`` bits from SOF to the end of the CRC; in the worst case one stuff bit is added
every four bits after the first, hence::

    bits(n) = 47 + 8 n + floor((34 + 8 n - 1) / 4)

An empty frame (SYNC) is 55 bits; an 8-byte frame is 111 bits unstuffed and 135 bits with
worst-case stuffing (the range quoted in ``notes/performance.md``).

Pure: no bus access.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
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
    """

    frames_per_cycle: int
    bits_per_cycle: int
    cycle_s: float
    bitrate: int

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
    pdo_lengths: Iterable[Sequence[int]], cycle_s: float, bitrate: int, *, sync: bool = True
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
    """
    frames = 1 if sync else 0
    bits = frame_bits(0) if sync else 0
    for lengths in pdo_lengths:
        for n in lengths:
            frames += 1
            bits += frame_bits(n)
    return BusLoad(frames, bits, float(cycle_s), int(bitrate))


def check_load(load: BusLoad, max_share: float, source: str = "campaign") -> None:
    """Refuse a configuration whose cyclic traffic exceeds ``max_share`` of the bit rate.

    Raises
    ------
    daq.ConfigError
        ``"<source>: daq.max_bus_load: cyclic traffic needs 81.0 % of ... > 60 %"``.
    """
    if load.share > max_share:
        raise ConfigError(
            f"{source}: daq.max_bus_load: cyclic traffic needs {load} "
            f"> allowed {100 * max_share:g} % (lower the rate or the PDOs, or raise the bit rate)"
        )
