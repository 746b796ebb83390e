"""The top of the package graph: the ``jointid`` entry point (:mod:`.cli`, dispatch only) and
the demo (:mod:`.demo`), which drives every other package."""
