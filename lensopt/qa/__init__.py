"""Quality assurance over whole lenses. Sits beside ``optim``/``imaging`` and uses them.

    check.py               regression checks against a baseline (``lensopt check``)
    accuracy.py            what accuracy costs in time (``lensopt accuracy``): spots, PSFs, simulation
    accuracy_analyses.py   the same for the wavefront, Seidel, field-curve, encircled-energy and MTF analyses
    measure.py             a measured setting (Point) and its median time
"""
