"""An evaluation of ``rocketid diagnose`` on a fin-stabilized sounding rocket: a short solid burn, a long coast.

Tern-2 (``tests/vehicles/tern.py``) leaves a 7 m rail at 84 deg and 37.6 m/s half a second after
ignition, burns out at 10.25 s near Mach 3.9 and coasts to 46 km by 60 s, at zero attack angle
(a gravity turn). ``truth.py`` flies it in another state space (three-dimensional position and
velocity about the Earth's centre, vector forces, its own 1976 atmosphere) with every hidden
effect in its own physical shape; ``cases.py`` lists the cases; ``run.py`` makes the data, runs
``rocketid diagnose`` from the command line on each and scores the result.
"""
