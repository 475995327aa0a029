"""An evaluation of ``rocketid diagnose`` on a high-site liquid booster and hidden physics never tuned on.

``truth.py`` flies Petrel-V (``tests/vehicles/petrel.py``) in its own state space (Earth-centred
Cartesian position and velocity in the trajectory plane) with its own 1976 atmosphere and every hidden
effect written apart from the effect catalogue; ``cases.py`` lists the cases; ``run.py`` makes the
data, runs ``rocketid diagnose`` from the command line on each and scores the result.
"""
