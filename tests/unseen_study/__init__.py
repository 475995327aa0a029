"""An evaluation of ``rocketid diagnose`` on a vehicle and hidden effects the team never tuned on.

``truth.py`` builds Kestrel-S's truth model (``tests/vehicles/kestrel.py``) in another state
space, with every hidden effect written apart from the effect catalogue; ``cases.py`` lists the
cases; ``run.py`` makes the data, runs ``rocketid diagnose`` from the command line on each and
scores the result.
"""
