"""The CANopen and log protocol shared by the master, the simulated drives and identification.

Pure tables and functions (no bus, no clock): the CiA 402 state machine and modes
(:mod:`.cia402`), the one position control law (:mod:`.control`), the MCAP log format
(:mod:`.logformat`: schemas, record layouts, dtypes, flags) and its reader (:mod:`.reader`,
the only module here that touches files). Imports nothing of :mod:`daq` but its exceptions.
"""
