"""An evaluation of ``rocketid diagnose`` on a hybrid-motor sounding rocket flown from a static firing's table
and tracked by GPS.

Wren-H (``tests/vehicles/wren.py``), an N2O / paraffin hybrid declared as a university team would: the static
firing's thrust and consumed-propellant tables, the launch mass weighed on the pad, the rail-exit states
from a 1-D integration, CD as a Mach table, no lift. ``truth.py`` flies it with its own motor (a
self-pressurizing N2O tank that blows down, a regressing paraffin port, chamber pressure from the injector
and the nozzle), its own Cartesian equations of motion and 1976 atmosphere, every hidden effect in its own
physical shape; ``cases.py`` lists the cases and their right answers; ``run.py`` makes the GPS logs, runs
``rocketid diagnose --sigma estimate`` from the command line on each, and scores the result.
"""
