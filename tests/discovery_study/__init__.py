"""The hidden-effect study of ``rocketid diagnose`` on independent data (issue 8).

``truth``    truth models written independently of the effect catalogue, and the measurements
``cases``    the study's cases as data (vehicle, hidden effects and sizes, seed)
``harness``  make each case's data (cached CSV), run the diagnosis, score it against the truth

``tests/test_discovery_study.py`` asserts the requirements; ``benchmarks/discovery_study.py``
runs the whole study and writes the table of ``docs/effects.md``.
"""
