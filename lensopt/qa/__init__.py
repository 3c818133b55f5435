"""Quality assurance over whole lenses. Sits beside ``optim``/``imaging`` and uses them.

    check.py      regression checks against a baseline (``lensopt check``)
    accuracy.py   what accuracy costs in time (``lensopt accuracy``)
"""
