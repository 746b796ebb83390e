"""CiA 402 (IEC 61800-7-201) drive state machine as pure, table-driven functions.

Used by both sides of the bus: the simulated drive (:mod:`sim_drivers`) computes its next
state and statusword from the controlword, and the master (:mod:`daq`) decodes statuswords
and computes the controlword sequence to reach a target state. No I/O here.

Transition numbers are the standard's (CiA 402-2, figure "state machine"):

====  =======================  ======================  ===============================
 no.  from                     to                      event
====  =======================  ======================  ===============================
  0   (power on)               NOT_READY_TO_SWITCH_ON  automatic
  1   NOT_READY_TO_SWITCH_ON   SWITCH_ON_DISABLED      automatic (self-test done)
  2   SWITCH_ON_DISABLED       READY_TO_SWITCH_ON      Shutdown
  3   READY_TO_SWITCH_ON       SWITCHED_ON             Switch on
  4   SWITCHED_ON              OPERATION_ENABLED       Enable operation
  5   OPERATION_ENABLED        SWITCHED_ON             Disable operation
  6   SWITCHED_ON              READY_TO_SWITCH_ON      Shutdown
  7   READY_TO_SWITCH_ON       SWITCH_ON_DISABLED      Disable voltage / Quick stop
  8   OPERATION_ENABLED        READY_TO_SWITCH_ON      Shutdown
  9   OPERATION_ENABLED        SWITCH_ON_DISABLED      Disable voltage
 10   SWITCHED_ON              SWITCH_ON_DISABLED      Disable voltage / Quick stop
 11   OPERATION_ENABLED        QUICK_STOP_ACTIVE       Quick stop
 12   QUICK_STOP_ACTIVE        SWITCH_ON_DISABLED      Disable voltage, or quick stop done
 13   (any)                    FAULT_REACTION_ACTIVE   fault detected
 14   FAULT_REACTION_ACTIVE    FAULT                   automatic (reaction done)
 15   FAULT                    SWITCH_ON_DISABLED      Fault reset (rising edge of bit 7)
 16   QUICK_STOP_ACTIVE        OPERATION_ENABLED       Enable operation (option code 5-8)
====  =======================  ======================  ===============================
"""

from __future__ import annotations

from collections import deque
from enum import IntEnum


class State(IntEnum):
    """Drive states; the values are for ordering only, not bus values."""

    NOT_READY_TO_SWITCH_ON = 0
    SWITCH_ON_DISABLED = 1
    READY_TO_SWITCH_ON = 2
    SWITCHED_ON = 3
    OPERATION_ENABLED = 4
    QUICK_STOP_ACTIVE = 5
    FAULT_REACTION_ACTIVE = 6
    FAULT = 7


class Mode(IntEnum):
    """Modes of operation (0x6060 / 0x6061)."""

    NO_MODE = 0
    PROFILE_POSITION = 1
    VELOCITY = 2
    PROFILE_VELOCITY = 3
    PROFILE_TORQUE = 4
    HOMING = 6
    INTERPOLATED_POSITION = 7
    CYCLIC_SYNC_POSITION = 8
    CYCLIC_SYNC_VELOCITY = 9
    CYCLIC_SYNC_TORQUE = 10


CYCLIC_MODES = frozenset(
    {Mode.CYCLIC_SYNC_POSITION, Mode.CYCLIC_SYNC_VELOCITY, Mode.CYCLIC_SYNC_TORQUE}
)

# 0x6502 "supported drive modes": bit index per mode (bit 4 is reserved).
SUPPORTED_MODE_BIT = {
    Mode.PROFILE_POSITION: 0,
    Mode.VELOCITY: 1,
    Mode.PROFILE_VELOCITY: 2,
    Mode.PROFILE_TORQUE: 3,
    Mode.HOMING: 5,
    Mode.INTERPOLATED_POSITION: 6,
    Mode.CYCLIC_SYNC_POSITION: 7,
    Mode.CYCLIC_SYNC_VELOCITY: 8,
    Mode.CYCLIC_SYNC_TORQUE: 9,
}


def supported_modes(mask: int) -> frozenset[Mode]:
    """Decode 0x6502 into the set of standard modes it advertises."""
    return frozenset(m for m, b in SUPPORTED_MODE_BIT.items() if mask >> b & 1)


def supported_modes_mask(modes: set[Mode] | frozenset[Mode]) -> int:
    """Encode a set of modes as a 0x6502 value."""
    return sum(1 << SUPPORTED_MODE_BIT[m] for m in modes)


# Statusword bits (0x6041).
SW_READY_TO_SWITCH_ON = 1 << 0
SW_SWITCHED_ON = 1 << 1
SW_OPERATION_ENABLED = 1 << 2
SW_FAULT = 1 << 3
SW_VOLTAGE_ENABLED = 1 << 4
SW_QUICK_STOP = 1 << 5  # 0 = quick stop active
SW_SWITCH_ON_DISABLED = 1 << 6
SW_WARNING = 1 << 7
SW_REMOTE = 1 << 9
SW_TARGET_REACHED = 1 << 10
SW_INTERNAL_LIMIT = 1 << 11
SW_OMS_12 = 1 << 12  # cyclic modes: "drive follows the command value"
SW_OMS_13 = 1 << 13  # CSP: following error

# (mask, value) of the state bits per state, from the standard's statusword table.
_STATUS_PATTERN: dict[State, tuple[int, int]] = {
    State.NOT_READY_TO_SWITCH_ON: (0x4F, 0x00),
    State.SWITCH_ON_DISABLED: (0x4F, 0x40),
    State.READY_TO_SWITCH_ON: (0x6F, 0x21),
    State.SWITCHED_ON: (0x6F, 0x23),
    State.OPERATION_ENABLED: (0x6F, 0x27),
    State.QUICK_STOP_ACTIVE: (0x6F, 0x07),
    State.FAULT_REACTION_ACTIVE: (0x4F, 0x0F),
    State.FAULT: (0x4F, 0x08),
}


def state_from_statusword(statusword: int) -> State:
    """Decode the state from a statusword (0x6041).

    Raises
    ------
    ValueError
        If the bits match no state of the standard.
    """
    for state, (mask, value) in _STATUS_PATTERN.items():
        if statusword & mask == value:
            return state
    raise ValueError(f"statusword 0x{statusword:04X} encodes no CiA 402 state")


def statusword(
    state: State,
    *,
    voltage_enabled: bool = True,
    warning: bool = False,
    remote: bool = True,
    target_reached: bool = False,
    internal_limit: bool = False,
    bit12: bool = False,
    bit13: bool = False,
) -> int:
    """Encode a statusword for ``state`` plus the given flag bits."""
    _, value = _STATUS_PATTERN[state]
    if state is State.READY_TO_SWITCH_ON or state is State.SWITCHED_ON:
        value |= SW_QUICK_STOP
    elif state is State.OPERATION_ENABLED:
        value |= SW_QUICK_STOP
    sw = value
    if voltage_enabled:
        sw |= SW_VOLTAGE_ENABLED
    if warning:
        sw |= SW_WARNING
    if remote:
        sw |= SW_REMOTE
    if target_reached:
        sw |= SW_TARGET_REACHED
    if internal_limit:
        sw |= SW_INTERNAL_LIMIT
    if bit12:
        sw |= SW_OMS_12
    if bit13:
        sw |= SW_OMS_13
    return sw


class Command(IntEnum):
    """Device-control commands encoded in controlword bits 0-3 and 7."""

    SHUTDOWN = 0x06
    SWITCH_ON = 0x07
    DISABLE_VOLTAGE = 0x00
    QUICK_STOP = 0x02
    DISABLE_OPERATION = 0x07
    ENABLE_OPERATION = 0x0F
    FAULT_RESET = 0x80


CW_FAULT_RESET = 1 << 7
CW_HALT = 1 << 8


def decode_command(controlword: int) -> str:
    """Name the device-control command in a controlword (bits 0-3, 7).

    Returns one of ``"shutdown"``, ``"switch_on"``, ``"enable_operation"``,
    ``"disable_voltage"``, ``"quick_stop"``, ``"fault_reset"`` (bit 7 set).
    ``"switch_on"`` doubles as "disable operation" (same bits, 0xxx 0111).
    """
    if controlword & CW_FAULT_RESET:
        return "fault_reset"
    if controlword & 0x02 == 0:
        return "disable_voltage"
    if controlword & 0x06 == 0x02:
        return "quick_stop"
    if controlword & 0x07 == 0x06:
        return "shutdown"
    if controlword & 0x0F == 0x07:
        return "switch_on"
    return "enable_operation"  # 0xxx 1111


# (from state, command) -> (to state, transition number)
TRANSITIONS: dict[tuple[State, str], tuple[State, int]] = {
    (State.SWITCH_ON_DISABLED, "shutdown"): (State.READY_TO_SWITCH_ON, 2),
    (State.READY_TO_SWITCH_ON, "switch_on"): (State.SWITCHED_ON, 3),
    (State.READY_TO_SWITCH_ON, "enable_operation"): (State.SWITCHED_ON, 3),
    (State.SWITCHED_ON, "enable_operation"): (State.OPERATION_ENABLED, 4),
    (State.OPERATION_ENABLED, "switch_on"): (State.SWITCHED_ON, 5),
    (State.SWITCHED_ON, "shutdown"): (State.READY_TO_SWITCH_ON, 6),
    (State.READY_TO_SWITCH_ON, "disable_voltage"): (State.SWITCH_ON_DISABLED, 7),
    (State.READY_TO_SWITCH_ON, "quick_stop"): (State.SWITCH_ON_DISABLED, 7),
    (State.OPERATION_ENABLED, "shutdown"): (State.READY_TO_SWITCH_ON, 8),
    (State.OPERATION_ENABLED, "disable_voltage"): (State.SWITCH_ON_DISABLED, 9),
    (State.SWITCHED_ON, "disable_voltage"): (State.SWITCH_ON_DISABLED, 10),
    (State.SWITCHED_ON, "quick_stop"): (State.SWITCH_ON_DISABLED, 10),
    (State.OPERATION_ENABLED, "quick_stop"): (State.QUICK_STOP_ACTIVE, 11),
    (State.QUICK_STOP_ACTIVE, "disable_voltage"): (State.SWITCH_ON_DISABLED, 12),
}

# Controlword that requests each transition (the master's side of the table).
TRANSITION_CONTROLWORD: dict[int, int] = {
    2: Command.SHUTDOWN,
    3: Command.SWITCH_ON,
    4: Command.ENABLE_OPERATION,
    5: Command.DISABLE_OPERATION,
    6: Command.SHUTDOWN,
    7: Command.DISABLE_VOLTAGE,
    8: Command.SHUTDOWN,
    9: Command.DISABLE_VOLTAGE,
    10: Command.DISABLE_VOLTAGE,
    11: Command.QUICK_STOP,
    12: Command.DISABLE_VOLTAGE,
    15: Command.FAULT_RESET,
    16: Command.ENABLE_OPERATION,
}


def next_state(
    state: State,
    controlword: int,
    previous_controlword: int,
    *,
    quick_stop_option: int = 2,
) -> tuple[State, int | None]:
    """Device side: the state after the drive receives ``controlword``.

    Parameters
    ----------
    state : State
        Current state.
    controlword, previous_controlword : int
        New and previous 0x6040 values (the fault reset acts on the rising edge of bit 7).
    quick_stop_option : int
        0x605A quick stop option code; with codes 5-8 the drive stays in QUICK_STOP_ACTIVE
        and "enable operation" returns to OPERATION_ENABLED (transition 16).

    Returns
    -------
    (State, int | None)
        The new state and the transition number taken, or ``(state, None)`` when the
        controlword requests no transition from ``state``. Automatic transitions (0, 1, 12
        after a completed quick stop, 13, 14) are not driven by the controlword: the drive
        applies them itself with :func:`automatic_transition`.
    """
    if state is State.FAULT:
        rising = controlword & CW_FAULT_RESET and not previous_controlword & CW_FAULT_RESET
        return (State.SWITCH_ON_DISABLED, 15) if rising else (state, None)
    if state in (State.FAULT_REACTION_ACTIVE, State.NOT_READY_TO_SWITCH_ON):
        return state, None
    cmd = decode_command(controlword)
    if cmd == "fault_reset":
        return state, None  # only meaningful in FAULT
    if state is State.QUICK_STOP_ACTIVE and cmd == "enable_operation":
        return (State.OPERATION_ENABLED, 16) if 5 <= quick_stop_option <= 8 else (state, None)
    hit = TRANSITIONS.get((state, cmd))
    return hit if hit is not None else (state, None)


def automatic_transition(state: State, event: str) -> tuple[State, int | None]:
    """Device side: the automatic transitions.

    ``event`` is ``"self_test_done"`` (1), ``"fault"`` (13, from any state but FAULT),
    ``"fault_reaction_done"`` (14) or ``"quick_stop_done"`` (12 with option codes 0-4).
    """
    if event == "fault" and state not in (State.FAULT, State.FAULT_REACTION_ACTIVE):
        return State.FAULT_REACTION_ACTIVE, 13
    if event == "fault_reaction_done" and state is State.FAULT_REACTION_ACTIVE:
        return State.FAULT, 14
    if event == "self_test_done" and state is State.NOT_READY_TO_SWITCH_ON:
        return State.SWITCH_ON_DISABLED, 1
    if event == "quick_stop_done" and state is State.QUICK_STOP_ACTIVE:
        return State.SWITCH_ON_DISABLED, 12
    return state, None


def path(start: State, goal: State) -> list[tuple[int, int]]:
    """Master side: the shortest list of ``(transition, controlword)`` from start to goal.

    FAULT is left by a fault reset (15): the returned controlword has bit 7 set; the caller
    must send a controlword with bit 7 clear before it (rising edge).

    Raises
    ------
    ValueError
        If no controlword-driven sequence reaches ``goal`` (e.g. goal is FAULT).
    """
    if start == goal:
        return []
    edges: dict[State, list[tuple[State, int]]] = {}
    for (src, _), (dst, number) in TRANSITIONS.items():
        edges.setdefault(src, []).append((dst, number))
    edges.setdefault(State.FAULT, []).append((State.SWITCH_ON_DISABLED, 15))
    seen = {start: []}
    queue = deque([start])
    while queue:
        s = queue.popleft()
        for dst, number in sorted(edges.get(s, []), key=lambda e: e[1]):
            if dst not in seen:
                seen[dst] = seen[s] + [(number, int(TRANSITION_CONTROLWORD[number]))]
                if dst == goal:
                    return seen[dst]
                queue.append(dst)
    raise ValueError(f"no controlword sequence leads from {start.name} to {goal.name}")
