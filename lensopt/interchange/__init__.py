"""Lens files of other programs ↔ lensopt specs. Ranked above ``spec``: the spec is the data model that a
file is read into and written from (as optiland's ``fileio`` shares one model).

    numbers.py   numbers written so that they read back as the same double (both formats)
    codev/       CODE V sequence files (.seq)
    zemax/       Zemax OpticStudio sequential files (.zmx)
"""
