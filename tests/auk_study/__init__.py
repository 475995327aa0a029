"""An evaluation of ``rocketid diagnose`` on a liquid core with two strap-on solid boosters jettisoned in flight.

Auk-B (``tests/vehicles/auk.py``) lifts off from a sea-level pad with a throttled liquid core and two
solid boosters whose casings leave the vehicle at 40 s. ``truth.py`` flies it in another state space
(radius, central angle and the radial and horizontal velocity about the Earth's centre, vector forces,
its own 1976 atmosphere, the jettison as a discontinuity) with every hidden effect written in its own
physical shape; ``cases.py`` lists the cases; ``run.py`` makes the data, runs ``rocketid diagnose`` from
the command line on each and scores the result.
"""
