"""An evaluation of ``rocketid diagnose`` on several flights of one vehicle whose noise nobody states.

A case is a **campaign**: three flights of Petrel-V (``tests/vehicles/petrel.py``) flown by the high-site
study's independent truth (``tests/petrel_study/truth.py``, imported, not changed). Each flight has its own
day -- its own noise seed, its own noise level (Petrel's GNSS scaled by a factor of its own) and possibly its
own wind or sensor bias -- and the campaign may hide one property of the vehicle in every flight.
``cases.py`` lists the campaigns and writes their CSVs without any sigma; ``run.py`` runs ``rocketid diagnose
A.csv B.csv C.csv --sigma estimate`` from the command line on each and scores each flight and the joint model.
"""
