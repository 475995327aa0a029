"""An evaluation of ``rocketid diagnose`` on telemetry as it really comes: unknown noise, multi-rate channels
with drop-outs and quantized words, a record that starts in flight.

Corvid-L (``tests/vehicles/corvid.py``), a guided liquid first stage with a commanded throttle bucket, a
stored pitch program and lift, launched from Andoya (69.29 N, azimuth 345 deg); its telemetry (speed
10 Hz, altitude 2 Hz, downrange 1 Hz with a radar hand-over gap) is acquired from T+12 s. ``truth.py``
flies it in another state space (Cartesian position and velocity about the Earth's centre, vector
forces, its own 1976 atmosphere) with every hidden effect in its own physical shape; ``cases.py``
lists the cases; ``run.py`` makes the data and runs ``rocketid diagnose --sigma estimate --window
12:`` from the command line on each, and scores the result.
"""
