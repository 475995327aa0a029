"""An evaluation of ``rocketid diagnose`` on an air-launched winged vehicle started in flight.

Osprey-A (``tests/vehicles/osprey.py``) is dropped from a carrier aircraft; the data start at
first-stage ignition at 11.8 km and Mach 0.8, slightly descending. ``truth.py`` flies it in
another state space (Cartesian position and velocity about the Earth's centre, vector forces, its
own 1976 atmosphere) with every hidden effect written in its own physical shape; ``cases.py``
lists the cases; ``run.py`` makes the data, runs ``rocketid diagnose`` from the command line on
each and scores the result.
"""
