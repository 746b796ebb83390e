"""The acquisition runtime: CANopen master, campaign runner, MCAP writer, ``jointid run``.

- :mod:`.config` (``[daq]`` table), :mod:`.busload` (bit-rate budget), :mod:`.master`
  (start-up, PDO layout read back, master heartbeat);
- :mod:`.runner` (campaign orchestration: bus, payload loop, operator, resume state),
  :mod:`.engine` (plan execution cycle by cycle), :mod:`.safety` (stop sequence, limits,
  watchdogs), :mod:`.cycle_io` (frames of a cycle), :mod:`.simrig` (``--simulate``);
- :mod:`.mcaplog` (the MCAP writer), :mod:`.progress` (progress line), :mod:`.cli`.

May import :mod:`daq.protocol`, :mod:`trajectories` and :mod:`sim_drivers` (``--simulate``);
never :mod:`ident`.
"""
